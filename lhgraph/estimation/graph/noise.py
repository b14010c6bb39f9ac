"""Variance-component adaptation of the noise levels: the hook the optimiser calls after every
accepted step.

The motion prior's covariance is rescaled until its whitened residuals have unit variance
per degree of freedom (so the prior matches how the board actually moved), within
[``min_psd_factor``, ``max_psd_factor``] times the configured PSDs; the diodes' noise is set to
the residuals' robust spread (MAD), within [1, ``max_sigma_factor``] times
``angle_sigma_rad`` (the 2 MHz quantisation). At most ``motion_prior_rounds`` updates change
the levels; an update whose ratios all lie in (0.8, 1.25) changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.options import GraphOptions

Progress = Callable[[str], None]


class NoiseAdaptation:
    """The noise hook of :func:`lhgraph.estimation.graph.optimizer.levenberg_marquardt` for
    ``evaluator``: ``hook(values)`` updates the levels at ``values`` and returns whether they
    changed (the cost at ``values`` must then be evaluated again)."""

    def __init__(self, evaluator: FactorEvaluator, options: GraphOptions,
                 progress: Progress | None = None):
        self.evaluator = evaluator
        self.options = options
        self.progress = progress
        self.rounds_left = options.motion_prior_rounds

    @staticmethod
    def enabled(options: GraphOptions) -> bool:
        """Whether ``options`` adapt any noise level."""
        return options.adapt_motion_prior or options.adapt_angle_sigma

    def __call__(self, values: gtsam.Values) -> bool:
        if self.rounds_left <= 0:
            return False
        self.evaluator.evaluate(values)
        changed = self._update()
        if changed:
            self.rounds_left -= 1
        return changed

    def _update(self) -> bool:
        """One variance-component update at the evaluator's current point; whether anything
        changed (False: both levels match the data or sit at their bounds)."""
        ev, options = self.evaluator, self.options
        chi2 = ev.motion_chi2_per_dof()
        ratio = float(np.clip(chi2, 1e-3, 1e3))
        if not options.adapt_motion_prior:
            ratio = 1.0
        # a model misfit shows up as board jitter: never loosen the prior beyond the cap
        ratio = min(ratio, options.max_psd_factor / ev.motion_psd_factor())
        # nor stiffen it below the floor: a real board's motion is not exactly WNOA, and an
        # over-stiff prior trades the station's accuracy for smoothness
        ratio = max(ratio, options.min_psd_factor / ev.motion_psd_factor())
        # the diodes' noise from the residuals (robust: MAD), never below the configured
        # sigma (the 2 MHz quantisation) nor above max_sigma_factor times it
        sigma_hat = 1.4826 * float(np.median(np.abs(ev.bearing_residuals())))
        noise = 1.0
        if options.adapt_angle_sigma:
            noise = float(np.clip(sigma_hat, options.angle_sigma_rad,
                                  options.max_sigma_factor * options.angle_sigma_rad)
                          / ev.angle_sigma())**2
        if self.progress:
            self.progress(f"motion prior: chi2/dof {chi2:.3g} (PSD scaled by {ratio:.3g}); "
                          f"angle noise {sigma_hat * 1e6:.1f} urad")
        if 0.8 < ratio < 1.25 and 0.8 < noise < 1.25:
            return False
        ev.scale_motion_prior(ratio)
        ev.scale_bearing_noise(noise)
        return True
