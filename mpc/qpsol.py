"""CasADi's QP solvers (``casadi.conic``) made without the banner qpOASES prints.

Every qpOASES instance prints its copyright notice when it is made, whatever its ``printLevel``
("none" silences its solves only): CasADi's wheels are built without CasADi's switch that
removes it, and CasADi passes qpOASES's output to Python's ``sys.stdout``. :func:`conic` takes
that notice out of what the construction prints and passes anything else on.
"""

from __future__ import annotations

import contextlib
import io
import re
import sys

import casadi as ca

#: qpOASES's copyright notice, from its first line to its last (qpOASES 3.2, src/Utils.cpp).
QPOASES_BANNER = re.compile(r"\n?qpOASES -- An Implementation of the Online Active Set Strategy\..*?"
                            r"See the GNU Lesser General Public License for more details\.\n*", re.S)


def conic(name: str, solver: str, spec: dict, opts: dict) -> ca.Function:
    """``casadi.conic(name, solver, spec, opts)``, without qpOASES's banner (module docstring)."""
    if solver != "qpoases":
        return ca.conic(name, solver, spec, opts)
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            return ca.conic(name, solver, spec, opts)
    finally:
        sys.stdout.write(QPOASES_BANNER.sub("", printed.getvalue()))
