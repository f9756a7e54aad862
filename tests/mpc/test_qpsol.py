"""mpc.qpsol.conic: a qpOASES QP made and solved prints nothing (qpOASES printed its copyright
notice on every instance made, printLevel "none" or not), what else the construction prints is
passed on, and the QP solves as CasADi's own."""

import casadi as ca
import pytest

from mpc import qpsol


def _qp(make):
    return make("q", "qpoases", {"h": ca.DM.eye(2).sparsity(), "a": ca.DM.ones(1, 2).sparsity()},
                {"printLevel": "none"})


def test_a_qpoases_qp_is_made_and_solved_without_its_banner(capfd):
    qp = _qp(qpsol.conic)
    sol = qp(h=ca.DM.eye(2), g=ca.DM([1.0, 3.0]), a=ca.DM.ones(1, 2), lba=-1.0, uba=1.0)
    assert capfd.readouterr() == ("", "")
    assert sol["x"].full().ravel().tolist() == pytest.approx([0.5, -1.5])  # min 0.5|x|^2 + g'x on x1 + x2 >= -1


def test_what_else_the_construction_prints_is_passed_on(capsys, monkeypatch):
    banner = ("\nqpOASES -- An Implementation of the Online Active Set Strategy.\nCopyright (C) 2007-2015\n"
              "See the GNU Lesser General Public License for more details.\n\n")

    def printing(*args):
        print(banner + "a warning of its own")
        return "the QP"

    monkeypatch.setattr(qpsol.ca, "conic", printing)
    assert _qp(qpsol.conic) == "the QP"
    assert capsys.readouterr().out == "a warning of its own\n"
