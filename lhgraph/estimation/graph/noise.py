"""Variance-component adaptation of the noise levels: the hook the optimiser calls after every
accepted step.

The motion prior's covariance is rescaled until its whitened residuals have unit variance
per degree of freedom (so the prior matches how the board actually moved), within
[``min_psd_factor``, ``max_psd_factor``] times the configured PSDs; with
``motion_prior_estimate = "redundancy"`` the degrees of freedom are the prior's redundancy
(:func:`redundancy`), not its row count, and there is no floor: the fit absorbs most of the
prior's residual (on a 2 s simulated capture 86 % of its rows' hat-matrix trace), so the plain
mean square underestimates the prior's variance several times over. The diodes' noise is set to
the residuals' robust spread (MAD), within [1, ``max_sigma_factor``] times
``angle_sigma_rad`` (the 2 MHz quantisation). With ``adapt_gyro_sigma`` and preintegrated
gyro factors, their reading noise is rescaled until their whitened residuals have unit
variance, within [the stream's own reading noise, ``gyro_sigma_rad_s``]: a fit that absorbs
part of the gyro's noise cannot take it below what the readings show, and a gyro that does not
fit the light (a scale error not solved) keeps the loose ceiling. At most
``motion_prior_rounds`` updates change the levels; an update whose ratios all lie within
:data:`SETTLED` (the angle noise's within :data:`ANGLE_SETTLED`) changes nothing. The
redundancy is computed again only after the levels changed: with them unchanged, the states
have settled and it barely moves.
"""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.imu.twist_terms import ImuTerms
from lhgraph.estimation.spread import robust_sigma

Progress = Callable[[str], None]
SETTLED = (0.8, 1.25)
"""An update whose variance ratios all lie in this band (the angle noise's in
:data:`ANGLE_SETTLED`) changes nothing."""
ANGLE_SETTLED = (1 / 1.02, 1.02)
"""The band of the angle noise's variance ratio. It was :data:`SETTLED`'s until 2026-12-08:
the angle noise then stopped anywhere within +-12 % of the residuals' spread, on the side it
came from, and a hive bag solved again from its own answer settled at 64 instead of 73-76
urad and moved station 1 by 1.3 mm (0.06-0.17 mm with this band,
benchmarks/start_dependence.py, docs/uncertainty.md). The other levels keep the wider band:
the few-diode motion prior's redundancy is a one-probe estimate, and with this band its
updates ran into ``motion_prior_rounds`` and moved a Crazyflie flight's answer by 1.9 mm
from its own start."""


REDUNDANCY_PROBES = 1
"""Random probes of the hat matrix's trace in :func:`redundancy`: one is enough, since an
update acts only when the ratio leaves :data:`SETTLED` (the redundancy's spread per probe:
under 1 % on a 2 s simulated capture, 0.9 % on a 120 s simulated deck, 8 probes)."""


def redundancy(lin: gtsam.GaussianFactorGraph, groups: list[range], ordering: gtsam.Ordering,
               probes: int = REDUNDANCY_PROBES, seed: int = 0,
               zero: gtsam.VectorValues | None = None) -> list[tuple[int, float]]:
    """Per group of linear factors (``groups``: index ranges) of the whitened least-squares
    system ``lin``: its rows ``n`` and redundancy ``n - trace(H)`` (``H = A_g N^-1 A_g^T``
    the group's block of the hat matrix, ``N = A^T A``): the degrees of freedom the fit
    leaves their residuals, so that ``e^T e / redundancy`` estimates their variance factor.
    The trace by Hutchinson's estimator over ``probes`` Rademacher vectors ``z`` (seeded: the
    same number for the same system): ``z^T A_g N^-1 A_g^T z = |R^-T A_g^T z|^2``, with
    ``N = R^T R`` from ``lin`` eliminated sequentially in ``ordering`` (once for every
    group). ``zero``: a vector for every variable of ``lin`` (any values: only its keys and
    dimensions count), made from ``lin`` when not given."""
    net = lin.eliminateSequential(ordering)
    rng = np.random.default_rng(seed)
    # a vector per variable, made in C++ when not given
    every_key = lin.gradientAtZero() if zero is None else zero
    out = []
    for factors in groups:
        members = [lin.at(i) for i in factors]
        rows = np.array([f.rows() for f in members])
        bounds = np.r_[0, np.cumsum(rows)]
        traces = []
        for _ in range(probes):
            g = gtsam.VectorValues.Zero(every_key)
            z = rng.choice([-1.0, 1.0], int(bounds[-1]))
            for f, a, e in zip(members, bounds[:-1], bounds[1:], strict=True):
                f.transposeMultiplyAdd(1.0, z[a:e], g)
            traces.append(float(np.sum(net.backSubstituteTranspose(g).vector() ** 2)))
        n = int(bounds[-1])
        out.append((n, n - float(np.mean(traces))))
    return out


class NoiseAdaptation:
    """The noise hook of :func:`lhgraph.estimation.graph.optimizer.levenberg_marquardt` for
    ``evaluator``: ``hook(values)`` updates the levels at ``values`` and returns whether they
    changed (the cost at ``values`` must then be evaluated again); ``graph`` is the graph whose
    callbacks ``evaluator`` serves (``motion_prior_estimate = "redundancy"`` linearises it)."""

    def __init__(self, graph: gtsam.NonlinearFactorGraph, evaluator: FactorEvaluator,
                 options: GraphOptions, progress: Progress | None = None):
        self.evaluator = evaluator
        self.options = options
        self.progress = progress
        self.graph = graph
        self.rounds_left = options.motion.motion_prior_rounds
        self._redundancy: dict[str, tuple[int, float]] | None = None  # at the current levels
        self._keys: gtsam.VectorValues | None = None  # a vector per variable (the graph's)

    @staticmethod
    def enabled(options: GraphOptions) -> bool:
        """Whether ``options`` adapt any noise level."""
        return (options.motion.adapt_motion_prior or options.noise.adapt_angle_sigma
                or options.imu.adapt_gyro_sigma or options.imu.accel_sigma_estimate == "redundancy")

    def __call__(self, values: gtsam.Values,
                 linearized: Callable[[], gtsam.GaussianFactorGraph] | None = None) -> bool:
        """Update the levels at ``values`` (``linearized``: the graph linearised there, when
        the caller has it or will make it anyway); whether they changed."""
        if self.rounds_left <= 0:
            return False
        self.evaluator.evaluate(values)
        changed = self._update(values, linearized or (lambda: self.graph.linearize(values)))
        if changed:
            self.rounds_left -= 1
        return changed

    def _update(self, values: gtsam.Values,
                linearized: Callable[[], gtsam.GaussianFactorGraph]) -> bool:
        """One variance-component update at the evaluator's current point; whether anything
        changed (False: both levels match the data or sit at their bounds)."""
        ev, options = self.evaluator, self.options
        chi2 = ev.motion.chi2_per_dof()
        redundant = options.motion.motion_prior_estimate == "redundancy"
        groups = self._redundancy_groups()
        if groups and self._redundancy is None:
            self._redundancy = self._redundancies(linearized(), groups)
        if "motion" in groups:
            rows, dof = self._redundancy["motion"]
            chi2 *= rows / max(dof, 1.0)
        ratio = float(np.clip(chi2, 1e-3, 1e3))
        if not options.motion.adapt_motion_prior:
            ratio = 1.0
        # a model misfit shows up as board jitter: never loosen the prior beyond the cap
        ratio = min(ratio, options.motion.max_psd_factor / ev.motion.psd_factor())
        if not redundant:
            # nor stiffen it below the floor: a real board's motion is not exactly WNOA, and
            # an over-stiff prior trades the station's accuracy for smoothness
            ratio = max(ratio, options.motion.min_psd_factor / ev.motion.psd_factor())
        # the diodes' noise from the residuals (robust: MAD), never below the configured
        # sigma (the 2 MHz quantisation) nor above max_sigma_factor times it
        sigma_hat = robust_sigma(ev.bearing.residuals(), about_zero=True)
        noise = 1.0
        if options.noise.adapt_angle_sigma:
            noise = float(np.clip(sigma_hat, options.noise.angle_sigma_rad,
                                  options.noise.max_sigma_factor * options.noise.angle_sigma_rad)
                          / ev.bearing.angle_sigma())**2
        twist = ev.twist_imu
        imu = None if twist is None else twist.preintegrated()
        gyro = 1.0 if imu is None else self._gyro_ratio(imu)
        accel = self._accel_ratio() if "accel" in groups else 1.0
        if self.progress:
            self.progress(f"motion prior: chi2/dof {chi2:.3g} (PSD scaled by {ratio:.3g}); "
                          f"angle noise {sigma_hat * 1e6:.1f} urad"
                          + ("" if imu is None else
                             f"; preintegrated gyro noise "
                             f"{imu.preintegration_sigma() * np.sqrt(gyro):.2g} rad/s")
                          + ("" if "accel" not in groups else
                             f"; accelerometer noise "
                             f"{twist.terms.accel_sigma() * np.sqrt(accel):.2g} m/s^2"))
        if (all(SETTLED[0] < r < SETTLED[1] for r in (ratio, gyro, accel))
                and ANGLE_SETTLED[0] < noise < ANGLE_SETTLED[1]):
            return False
        ev.motion.scale(ratio)
        ev.bearing.scale_noise(noise)
        if twist is not None:
            twist.scale_preintegration_noise(gyro)
            twist.scale_accel_noise(accel)
        self._redundancy = None
        return True

    def _gyro_ratio(self, imu: ImuTerms) -> float:
        """The variance factor of ``imu``'s preintegrated gyro factors: their chi2 per degree
        of freedom, within [the stream's reading noise, ``gyro_sigma_rad_s``] (1 without
        ``adapt_gyro_sigma``)."""
        if not self.options.imu.adapt_gyro_sigma:
            return 1.0
        now = imu.preintegration_sigma()
        return float(np.clip(imu.preintegration_chi2_per_dof(), (imu.reading_sigma / now) ** 2,
                             (self.options.imu.gyro_sigma_rad_s / now) ** 2))

    def _accel_ratio(self) -> float:
        """The variance factor of the accelerometer factors: their whitened chi2 over their
        redundancy, within what keeps their median noise in the options' bounds."""
        imu = self.evaluator.twist_imu.terms
        rows, dof = self._redundancy["accel"]
        ok = imu.data.force_ok
        chi2 = float(np.sum((imu.a_scaled[ok] / imu.accel_sigmas[ok, None]) ** 2))
        low, high = imu.accel_bounds
        now = imu.accel_sigma()
        return float(np.clip(chi2 / max(dof, 1.0), (low / now) ** 2, (high / now) ** 2))

    def _redundancy_groups(self) -> dict[str, range]:
        """The factor groups whose variance factors count over their redundancy: the motion
        prior (``motion_prior_estimate = "redundancy"``) and the accelerometer factors
        (``accel_sigma_estimate = "redundancy"``, with IMU factors)."""
        ev, options = self.evaluator, self.options
        groups = {}
        motion = options.motion
        if motion.motion_prior_estimate == "redundancy" and motion.adapt_motion_prior:
            groups["motion"] = ev.motion.indices
        if (options.imu.accel_sigma_estimate == "redundancy" and ev.twist_imu is not None
                and len(ev.twist_imu.accel)):
            groups["accel"] = ev.twist_imu.accel
        return groups

    def _redundancies(self, lin: gtsam.GaussianFactorGraph, groups: dict[str, range]
                      ) -> dict[str, tuple[int, float]]:
        """Rows and redundancy of each of ``groups`` in the linearised graph ``lin``
        (:func:`redundancy`)."""
        if self._keys is None:
            self._keys = lin.gradientAtZero()
        found = redundancy(lin, list(groups.values()),
                           self.evaluator.layout.elimination_ordering(), zero=self._keys)
        return dict(zip(groups, found, strict=True))
