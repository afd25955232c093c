"""The simulation-versus-measurement gap: measurement campaigns, candidate effects fitted with
uncertainty, forward selection by information criterion, identifiability, ties and the
residual that stays unexplained (`analysis`). What predicts the baseline lives with the caller
(`service.gap`), which may use the absorber."""

from posedyn.gap.analysis import (
    LIBRARY, CandidateEffect, Fit, GapResult, Measurements, Noise, Parameter, analyse, chi2_p, confounded, fit, fit_noise, noise_verdict,
    predict, residual_correlates, separating_measurement,
)

__all__ = [
    "LIBRARY", "CandidateEffect", "Fit", "GapResult", "Measurements", "Noise", "Parameter", "analyse", "chi2_p", "confounded", "fit",
    "fit_noise", "noise_verdict", "predict", "residual_correlates", "separating_measurement",
]
