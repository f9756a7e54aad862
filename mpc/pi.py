"""Discrete PI controller (P80 -> feed rate) with anti-windup, bounds and rate limits; SIMC tuning.

The "reactive practice" baseline of issue 5: a single loop from the measured product size to
the feed rate.

Tuning: SIMC rules of S. Skogestad (2003), "Simple analytic rules for model reduction and PID
controller tuning", Journal of Process Control 13, 291-309, for a first-order-plus-dead-time
model ``k exp(-theta s) / (tau1 s + 1)``:

    Kc = tau1 / (k (tau_c + theta)),   Ti = min(tau1, 4 (tau_c + theta)),

with the closed-loop time constant ``tau_c`` a tuning knob; Skogestad recommends
``tau_c = theta`` for tight control with good robustness (the default here).

Control law (position form, integral by forward Euler), at each sample:

    e = r - y,   v = u_bias + Kc e + I,   u = sat(v)

where ``sat`` clips to ``[u_min, u_max]`` and to ``u_prev +- du_max`` (rate limit per sample).
Anti-windup, chosen with ``anti_windup``:

- ``"back_calculation"`` (default): ``I += Kc dt / Ti * e + dt / Tt * (u - v)``: when the
  actuator saturates the integral is driven back so that ``v`` tracks ``u`` with time constant
  ``Tt`` (K.J. Astrom and R.M. Murray, *Feedback Systems*, 2008, chapter 10 "PID Control",
  section "Integrator Windup"; Astrom and Hagglund, *PID Controllers*, 2nd ed., 1995, section
  3.5). They advise
  ``Tt`` between ``Td`` and ``Ti``; with no derivative action we default to ``Tt = Ti / 2``.
  Because the clipped ``u`` includes the rate limit, rate saturation does not wind up either.
- ``"conditional"``: conditional integration (Astrom and Hagglund 1995, section 3.5): the
  integral is frozen while the actuator is saturated and the error would push it further
  into saturation.
- ``"none"``: plain integration (for comparison only).
"""

from __future__ import annotations

import time

import numpy as np

from mpc.errors import MpcInputError, is_real
from mpc.linear import Fopdt, fopdt_from_model, linearize
from mpc.results import ControllerStepResult

ANTI_WINDUP = ("back_calculation", "conditional", "none")


def simc_pi(model: Fopdt, tau_c_h: float | None = None) -> tuple[float, float]:
    """SIMC PI settings ``(kc, ti_h)`` for a FOPDT model (Skogestad 2003).

    ``tau_c_h`` defaults to the dead time (Skogestad's recommendation); it must be given
    when the model has no dead time.
    """
    if not isinstance(model, Fopdt):
        raise MpcInputError(f"The 'model' parameter of simc_pi must be a Fopdt. Got {model!r}.")
    if not (np.isfinite(model.gain) and model.gain != 0):
        raise MpcInputError(f"The 'gain' of the FOPDT model must be finite and nonzero. "
                            f"Got {model.gain!r}.")
    if not (np.isfinite(model.tau_h) and model.tau_h > 0):
        raise MpcInputError(f"The 'tau_h' of the FOPDT model must be > 0. Got {model.tau_h!r}.")
    if not (np.isfinite(model.delay_h) and model.delay_h >= 0):
        raise MpcInputError(f"The 'delay_h' of the FOPDT model must be >= 0. "
                            f"Got {model.delay_h!r}.")
    tau_c = model.delay_h if tau_c_h is None else _float("tau_c_h", tau_c_h, "simc_pi")
    if not (np.isfinite(tau_c) and tau_c > 0):
        raise MpcInputError(
            f"The 'tau_c_h' parameter of simc_pi must be > 0 (it defaults to the dead time, "
            f"which is {model.delay_h!r}). Got {tau_c_h!r}."
        )
    kc = model.tau_h / (model.gain * (tau_c + model.delay_h))
    ti = min(model.tau_h, 4.0 * (tau_c + model.delay_h))
    return float(kc), float(ti)


def _float(name: str, value, owner: str = "DiscretePI") -> float:
    """``value`` as a float, or a refusal naming the parameter (a string or a bool is not a number here)."""
    if is_real(value):
        return float(value)
    raise MpcInputError(f"The '{name}' parameter of {owner} must be a float. Got {value!r}.")


def _positive(name: str, value: float) -> float:
    value = _float(name, value)
    if not (np.isfinite(value) and value > 0):
        raise MpcInputError(f"The '{name}' parameter of DiscretePI must be a float > 0. "
                            f"Got {value!r}.")
    return value


class DiscretePI:
    """Discrete PI controller with bounds, rate limit and anti-windup.

    Parameters
    ----------
    kc : float
        Proportional gain, input units per output unit (e.g. (t/h) per um). Its sign is the
        sign of the process gain.
    ti_h : float
        Integral time, hours.
    dt_h : float
        Sample period, hours.
    setpoint : float
        Output set point (e.g. P80 in um).
    u_bias : float
        Input at zero error and zero integral (the operating point, e.g. feed in t/h).
    u_min, u_max : float
        Input bounds.
    du_max : float
        Largest input change per sample (``inf``: no rate limit).
    anti_windup : str
        ``"back_calculation"``, ``"conditional"`` or ``"none"``.
    tt_h : float, optional
        Tracking time of back-calculation (default ``ti_h / 2``, at least ``dt_h``: the discrete
        back-calculation gain dt/Tt must not exceed 1); needs ``dt_h <= tt_h``.
    """

    def __init__(self, kc: float, ti_h: float, dt_h: float, setpoint: float, u_bias: float,
                 u_min: float = -np.inf, u_max: float = np.inf, du_max: float = np.inf,
                 anti_windup: str = "back_calculation", tt_h: float | None = None):
        kc = _float("kc", kc)
        if not (np.isfinite(kc) and kc != 0):
            raise MpcInputError(f"The 'kc' parameter of DiscretePI must be finite and nonzero. "
                                f"Got {kc!r}.")
        self.kc = kc
        self.ti_h = _positive("ti_h", ti_h)
        self.dt_h = _positive("dt_h", dt_h)
        if anti_windup not in ANTI_WINDUP:
            raise MpcInputError(f"The 'anti_windup' parameter of DiscretePI must be one of "
                                f"{ANTI_WINDUP}. Got {anti_windup!r}.")
        self.anti_windup = anti_windup
        self.tt_h = max(self.ti_h / 2.0, self.dt_h) if tt_h is None else _positive("tt_h", tt_h)
        if anti_windup == "back_calculation" and self.dt_h > self.tt_h:
            raise MpcInputError(f"The 'tt_h' parameter of DiscretePI must be >= dt_h "
                                f"({self.dt_h}) for a stable back-calculation. Got {self.tt_h}.")
        self.u_min, self.u_max = _float("u_min", u_min), _float("u_max", u_max)
        if not self.u_min < self.u_max:
            raise MpcInputError(f"The 'u_min' parameter of DiscretePI must be < u_max "
                                f"({self.u_max}). Got {self.u_min}.")
        self.du_max = _float("du_max", du_max)
        if not (self.du_max > 0):  # inf allowed: no rate limit
            raise MpcInputError(f"The 'du_max' parameter of DiscretePI must be > 0 (inf for no "
                                f"rate limit). Got {du_max!r}.")
        self.setpoint = _float("setpoint", setpoint)
        self.u_bias = _float("u_bias", u_bias)
        if not (np.isfinite(self.setpoint) and np.isfinite(self.u_bias)):
            raise MpcInputError("The 'setpoint' and 'u_bias' parameters of DiscretePI must be "
                                f"finite. Got {setpoint!r}, {u_bias!r}.")
        self.reset()

    @classmethod
    def from_fopdt(cls, model: Fopdt, dt_h: float, setpoint: float, u_bias: float,
                   tau_c_h: float | None = None, **kwargs) -> "DiscretePI":
        """A PI tuned by SIMC (:func:`simc_pi`) for the FOPDT ``model``."""
        kc, ti = simc_pi(model, tau_c_h)
        return cls(kc, ti, dt_h, setpoint, u_bias, **kwargs)

    def reset(self, u_prev: float | None = None) -> None:
        """Zero the integral; set the last applied input (default: ``u_bias`` clipped)."""
        self.integral = 0.0
        self.u_prev = float(np.clip(self.u_bias if u_prev is None else u_prev,
                                    self.u_min, self.u_max))
        self.last_result: ControllerStepResult | None = None

    def make_step(self, y_measured: float) -> float:
        """One sample: from the measured output to the input to apply.

        Also sets :attr:`last_result` (a :class:`ControllerStepResult` with status
        ``"linear"`` or ``"saturated"`` and ``cost`` the squared control error).
        """
        t0 = time.perf_counter()
        y = float(y_measured)
        if not np.isfinite(y):
            raise MpcInputError(f"The 'y_measured' parameter of DiscretePI.make_step must be "
                                f"finite. Got {y_measured!r}.")
        e = self.setpoint - y
        v = self.u_bias + self.kc * e + self.integral
        lo = max(self.u_min, self.u_prev - self.du_max)
        hi = min(self.u_max, self.u_prev + self.du_max)
        u = float(np.clip(v, lo, hi))
        di = self.kc * self.dt_h / self.ti_h * e
        if self.anti_windup == "back_calculation":
            self.integral += di + self.dt_h / self.tt_h * (u - v)
        elif self.anti_windup == "conditional":
            saturated_high = v > hi and di > 0
            saturated_low = v < lo and di < 0
            if not (saturated_high or saturated_low):
                self.integral += di
        else:
            self.integral += di
        self.u_prev = u
        status = "saturated" if u != v else "linear"
        self.last_result = ControllerStepResult(
            True, status, float(e * e), 0, time.perf_counter() - t0, [u], None, None
        )
        return u


def pi_from_model(f, outputs, x_ss, u_ss, d_ss, dt_h: float, setpoint: float | None = None,
                  output_name: str = "p80_um", input_name: str = "feed_tph",
                  input_names: tuple[str, ...] = ("feed_tph", "speed_frac_critical"),
                  tau_c_h: float | None = None, **kwargs) -> tuple["DiscretePI", Fopdt]:
    """The reactive baseline in one call: linearise the model at the steady state
    ``(x_ss, u_ss, d_ss)``, fit a FOPDT to the ``input_name -> output_name`` step response
    (:func:`mpc.linear.fopdt_from_model`), tune by SIMC and return ``(pi, fopdt)``.

    ``setpoint`` defaults to the output at the operating point; ``u_bias`` is the operating
    input; further keyword arguments (``u_min``, ``u_max``, ``du_max``, ``anti_windup``,
    ``tt_h``) go to :class:`DiscretePI`.
    """
    if input_name not in input_names:
        raise MpcInputError(f"The 'input_name' parameter of pi_from_model must be one of "
                            f"{input_names}. Got {input_name!r}.")
    sys_c, op = linearize(f, outputs, x_ss, u_ss, d_ss, [output_name], input_names=input_names)
    model = fopdt_from_model(sys_c, input_name, output_name)
    sp = float(op.y_ss[0]) if setpoint is None else float(setpoint)
    u_bias = float(op.u_ss[input_names.index(input_name)])
    return DiscretePI.from_fopdt(model, dt_h, sp, u_bias, tau_c_h=tau_c_h, **kwargs), model
