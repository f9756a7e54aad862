"""Calibration of bond strength (and stiffness) to laboratory compression tests, scikit-learn style.

``BondCalibrator(...)`` only stores its arguments; ``fit(target_peak_force_N, ...)`` builds
``n_particles`` seeded random agglomerates (the laboratory's ten particles), compresses each
with :func:`dem.lab.compression_test`, and adjusts the bond parameters until the *mean*
simulated peak force matches the target (and, if given, the mean secant stiffness matches a
target stiffness). Learned attributes end in ``_``.

Scaling used to need few simulations (Potyondy & Cundall 2004 §3.2: with the stiffness ratio
and the strength ratio held fixed, peak force is proportional to bond strength and the
pre-peak stiffness to bond stiffness): the first iteration multiplies the strengths by
``target/mean peak`` and the stiffnesses by ``target stiffness/mean stiffness``; later ones use
the measured exponent of ``F ~ sigma^p`` from the last two iterations (log-log secant). The same
agglomerates are reused in every iteration (common random numbers), so the iteration converges
on the model, not on noise; usually 2–3 iterations of ``n_particles`` tests.

Nothing here is an ore-specific number: targets come from the caller (``twin`` derives them);
the defaults are the issue's benchmark material (E = 30 GPa, ks/kn = 0.4, cohesion/tensile = 2).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd

from dem.agglomerate import make_agglomerate
from dem.bonds import BondParams, kn_from_modulus_Pa_m
from dem.errors import DemError, DemInputError
from dem.lab import DEFAULT_TIME_STEP_FACTOR, compression_test
from dem.materials import MIN_YOUNGS_MODULUS_PA, Material
from dem.parallel import run_in_processes


def _pos(owner, name, value, lo=0.0, hi=math.inf, integer=False):
    ok = (isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.floating, np.integer))
          ) and not isinstance(value, (bool, np.bool_))  # True was 1 particle, seed 1
    if not ok or not (math.isfinite(float(value)) and lo < float(value) <= hi):
        kind = "an int" if integer else "a float"
        raise DemInputError(f"The '{name}' parameter of {owner} must be {kind} in ({lo}, {hi}]. Got {value!r}.")
    return value


class BondCalibrator:
    """Fit bond strength (and stiffness) so simulated compression tests match a peak force.

    Parameters (stored unchanged; validated in ``fit``)
    ----------
    n_particles : number of random agglomerates (>= 10 to match the lab's ten particles).
    particle_diameter_m : particle size (the -25+19 mm class: 0.022 m).
    spheres_per_particle : spheres in each agglomerate (the resolution knob).
    random_state : seed; agglomerate k uses ``random_state + k``.
    material : sphere contact material (its density is the rock density).
    bond_modulus_Pa : initial bond modulus, ``k_n = E_b / (2 r_mean)`` (P&C 2004 eq. 9).
    stiffness_ratio : k_s / k_n.
    cohesion_ratio : cohesion / tensile strength.
    initial_tensile_strength_Pa : starting guess.
    friction_angle_deg, radius_multiplier, moment_factor : see :class:`dem.bonds.BondParams`.
    platen_speed_m_s, time_step_factor, local_damping : passed to the compression test.
    tol_pct : stop when the peak-force (and stiffness) errors are below this (%).
    max_iter : most scaling iterations.
    verbose : print each iteration.
    n_jobs : processes that run an iteration's compression tests (1: this one); the fit is the
        same for any number (:mod:`dem.parallel`).
    """

    def __init__(self, n_particles: int = 10, particle_diameter_m: float = 0.022,
                 spheres_per_particle: int = 250, random_state: int = 0, *,
                 material: Material = Material(), bond_modulus_Pa: float = 30e9,
                 stiffness_ratio: float = 0.4, cohesion_ratio: float = 2.0,
                 initial_tensile_strength_Pa: float = 10e6, friction_angle_deg: float = 0.0,
                 radius_multiplier: float = 1.0, moment_factor: float = 1.0,
                 platen_speed_m_s: float = 0.1, time_step_factor: float = DEFAULT_TIME_STEP_FACTOR,
                 local_damping: float = 0.7, tol_pct: float = 1.0, max_iter: int = 6,
                 verbose: bool = False, n_jobs: int = 1) -> None:
        self.n_particles = n_particles
        self.particle_diameter_m = particle_diameter_m
        self.spheres_per_particle = spheres_per_particle
        self.random_state = random_state
        self.material = material
        self.bond_modulus_Pa = bond_modulus_Pa
        self.stiffness_ratio = stiffness_ratio
        self.cohesion_ratio = cohesion_ratio
        self.initial_tensile_strength_Pa = initial_tensile_strength_Pa
        self.friction_angle_deg = friction_angle_deg
        self.radius_multiplier = radius_multiplier
        self.moment_factor = moment_factor
        self.platen_speed_m_s = platen_speed_m_s
        self.time_step_factor = time_step_factor
        self.local_damping = local_damping
        self.tol_pct = tol_pct
        self.max_iter = max_iter
        self.verbose = verbose
        self.n_jobs = n_jobs

    def get_params(self) -> dict:
        return {k: getattr(self, k) for k in (
            "n_particles", "particle_diameter_m", "spheres_per_particle", "random_state",
            "material", "bond_modulus_Pa", "stiffness_ratio", "cohesion_ratio",
            "initial_tensile_strength_Pa", "friction_angle_deg", "radius_multiplier",
            "moment_factor", "platen_speed_m_s", "time_step_factor", "local_damping", "tol_pct",
            "max_iter", "verbose", "n_jobs")}

    def _validate(self) -> None:
        o = "BondCalibrator"
        _pos(o, "n_particles", self.n_particles, 0, 10_000, integer=True)
        _pos(o, "particle_diameter_m", self.particle_diameter_m, 0.0, 1.0)
        _pos(o, "spheres_per_particle", self.spheres_per_particle, 1, 200_000, integer=True)
        _pos(o, "bond_modulus_Pa", self.bond_modulus_Pa, MIN_YOUNGS_MODULUS_PA, 1e13)  # a modulus in GPa is refused
        _pos(o, "stiffness_ratio", self.stiffness_ratio, 0.0, 10.0)
        _pos(o, "cohesion_ratio", self.cohesion_ratio, 0.0, 100.0)
        _pos(o, "initial_tensile_strength_Pa", self.initial_tensile_strength_Pa, 0.0, 1e11)
        _pos(o, "tol_pct", self.tol_pct, 0.0, 100.0)
        _pos(o, "max_iter", self.max_iter, 0, 100, integer=True)
        _pos(o, "n_jobs", self.n_jobs, 0, 1024, integer=True)
        if not isinstance(self.random_state, (int, np.integer)) or self.random_state < 0:
            raise DemInputError(
                f"The 'random_state' parameter of BondCalibrator must be an int >= 0. Got {self.random_state!r}.")
        if not isinstance(self.material, Material):
            raise DemInputError(
                f"The 'material' parameter of BondCalibrator must be a dem.materials.Material. Got {self.material!r}.")
        # what the compression tests and bonds would refuse, refused before any packing is made
        _pos(o, "platen_speed_m_s", self.platen_speed_m_s, 0.0, 10.0)
        _pos(o, "time_step_factor", self.time_step_factor, 0.0, 1.0)
        ld = self.local_damping
        if not (isinstance(ld, (int, float, np.floating, np.integer)) and 0.0 <= float(ld) < 1.0):
            raise DemInputError(
                f"The 'local_damping' parameter of BondCalibrator must be a float in [0, 1). Got {ld!r}.")
        self.params(1e12, float(self.initial_tensile_strength_Pa))  # friction angle, radius, moment factor

    def particle(self, k: int):
        """The k-th of the calibration's packings (seeded ``random_state + k``)."""
        return make_agglomerate(self.particle_diameter_m, self.spheres_per_particle,
                                random_state=int(self.random_state) + k)

    def params(self, kn_Pa_m: float, tensile_strength_Pa: float) -> BondParams:
        """The bonds :meth:`fit` tries at normal stiffness ``kn_Pa_m`` and tensile strength
        ``tensile_strength_Pa`` (shear stiffness and cohesion in the calibrator's ratios)."""
        return BondParams(kn_Pa_m=kn_Pa_m, ks_Pa_m=self.stiffness_ratio * kn_Pa_m,
                          tensile_strength_Pa=tensile_strength_Pa,
                          cohesion_Pa=self.cohesion_ratio * tensile_strength_Pa,
                          friction_angle_deg=self.friction_angle_deg,
                          radius_multiplier=self.radius_multiplier, moment_factor=self.moment_factor)

    def run(self, aggs, params: BondParams):
        """The compression tests of packings ``aggs`` with bonds ``params``, as :meth:`fit` runs them."""
        kw = {"material": self.material, "platen_speed_m_s": self.platen_speed_m_s,
              "local_damping": self.local_damping, "time_step_factor": self.time_step_factor}
        return run_in_processes(compression_test, [((a, params), kw) for a in aggs], self.n_jobs)

    def fit(self, target_peak_force_N: float, target_stiffness_N_m: float | None = None) -> "BondCalibrator":
        """Fit strengths (and stiffnesses if ``target_stiffness_N_m`` is given); returns self.

        Learned attributes: ``tensile_strength_Pa_``, ``cohesion_Pa_``, ``kn_Pa_m_``,
        ``ks_Pa_m_``, ``bond_params_``, ``peak_force_N_`` (per particle), ``mean_peak_force_N_``,
        ``calibration_error_pct_`` (|mean peak - target| / target, %), ``peak_force_cv_pct_``
        (particle-to-particle scatter), ``stiffness_N_m_`` (per particle),
        ``stiffness_error_pct_`` (nan without a stiffness target), ``fracture_energy_J_``,
        ``specific_fracture_energy_J_kg_`` (per particle), ``n_iter_``, ``best_iteration_`` (the
        iteration whose parameters are returned: the one with the smallest error),
        ``n_simulations_``,
        ``history_`` (DataFrame, one row per iteration), ``results_`` (last
        :class:`dem.lab.CompressionResult` list), ``fit_time_s_``.
        """
        self._validate()
        _pos("BondCalibrator.fit", "target_peak_force_N", target_peak_force_N, 0.0, 1e9)
        if target_stiffness_N_m is not None:
            _pos("BondCalibrator.fit", "target_stiffness_N_m", target_stiffness_N_m, 0.0, 1e15)
        t0 = time.perf_counter()
        aggs = [self.particle(k) for k in range(self.n_particles)]
        r_mean = float(np.mean([a.mean_radius_m for a in aggs]))
        kn = kn_from_modulus_Pa_m(self.bond_modulus_Pa, r_mean)
        sig = float(self.initial_tensile_strength_Pa)
        rows = []
        results = None
        best = None  # (error, params, results, peaks, stiff, mean_f, err_f, err_k, iteration)
        for it in range(1, self.max_iter + 1):
            params = self.params(kn, sig)
            results = self.run(aggs, params)
            peaks = np.array([r.peak_force_N for r in results])
            stiff = np.array([r.stiffness_N_m for r in results])
            mean_f = float(np.mean(peaks))
            mean_k = float(np.nanmean(stiff))
            err_f = abs(mean_f - target_peak_force_N) / target_peak_force_N * 100.0
            err_k = (abs(mean_k - target_stiffness_N_m) / target_stiffness_N_m * 100.0
                     if target_stiffness_N_m is not None else float("nan"))
            rows.append({"iteration": it, "tensile_strength_Pa": sig, "kn_Pa_m": kn,
                         "mean_peak_force_N": mean_f, "mean_stiffness_N_m": mean_k,
                         "peak_error_pct": err_f, "stiffness_error_pct": err_k})
            if self.verbose:
                print(f"BondCalibrator iteration {it}: {rows[-1]}", flush=True)
            score = err_f if target_stiffness_N_m is None else max(err_f, err_k)
            if best is None or score < best[0]:
                best = (score, params, results, peaks, stiff, mean_f, err_f, err_k, it)
            done = err_f <= self.tol_pct and (target_stiffness_N_m is None or err_k <= self.tol_pct)
            if done or it == self.max_iter:
                break
            if mean_f <= 0:
                raise DemError(f"Calibration failed: mean peak force {mean_f!r} N at iteration {it}.")
            # proportional scaling (see module docstring); from the second iteration on, the
            # exponent p of F ~ sigma^p is measured from the last two iterations (secant in
            # log-log), which removes the residual non-linearity (Hertz contacts, platens)
            p_exp = 1.0
            if len(rows) >= 2 and target_stiffness_N_m is None:
                s0, f0 = rows[-2]["tensile_strength_Pa"], rows[-2]["mean_peak_force_N"]
                if s0 != sig and f0 > 0:
                    p_exp = min(1.5, max(0.5, math.log(mean_f / f0) / math.log(sig / s0)))
            if target_stiffness_N_m is not None:
                kn *= target_stiffness_N_m / mean_k
            sig *= (target_peak_force_N / mean_f) ** (1.0 / p_exp)
        # the peak force is not a smooth function of strength (failure paths switch), so the
        # iteration may step past its best point: keep the best iteration
        _, params, results, peaks, stiff, mean_f, err_f, err_k, best_it = best
        whole = [k for k, r in enumerate(results) if not r.fractured]
        if whole:  # an end-of-travel force fitted as a strength
            raise DemError(f"Calibration failed: particles {whole} of the best iteration ({best_it}) did not fracture "
                           f"within the compression test's travel, so their peak force is no strength; the target "
                           f"{target_peak_force_N:g} N may be beyond what these bonds and materials reach.")
        self.best_iteration_ = int(best_it)
        self.bond_params_ = params
        self.tensile_strength_Pa_ = params.tensile_strength_Pa
        self.cohesion_Pa_ = params.cohesion_Pa
        self.kn_Pa_m_ = params.kn_Pa_m
        self.ks_Pa_m_ = params.ks_Pa_m
        self.peak_force_N_ = peaks
        self.mean_peak_force_N_ = mean_f
        self.calibration_error_pct_ = err_f
        self.peak_force_cv_pct_ = float(np.std(peaks, ddof=1) / mean_f * 100.0) if peaks.size > 1 else 0.0
        self.stiffness_N_m_ = stiff
        self.stiffness_error_pct_ = err_k
        self.fracture_energy_J_ = np.array([r.fracture_energy_J for r in results])
        self.specific_fracture_energy_J_kg_ = np.array([r.specific_fracture_energy_J_kg for r in results])
        self.n_iter_ = len(rows)
        self.n_simulations_ = len(rows) * self.n_particles
        self.history_ = pd.DataFrame(rows)
        self.results_ = results
        self.target_peak_force_N_ = float(target_peak_force_N)
        self.fit_time_s_ = time.perf_counter() - t0
        return self

    def results_frame(self) -> pd.DataFrame:
        """One row per particle of the last iteration (:meth:`CompressionResult.summary`)."""
        if not hasattr(self, "results_"):
            raise DemError("This BondCalibrator is not fitted yet; call fit() first.")
        df = pd.DataFrame([r.summary() for r in self.results_])
        df.insert(0, "particle", np.arange(len(df)))
        return df
