"""The gap workflow's runner side: the current model's predictions for a measurement campaign
and synthetic campaigns with effects hidden in them (`baseline`, which may use the absorber),
and the HTML report (`report`). The statistics live in `posedyn.gap`."""

from service.gap.baseline import Baseline, campaign_design, campaign_poses, generate_measurements, hide
from service.gap.report import render

__all__ = ["Baseline", "campaign_design", "campaign_poses", "generate_measurements", "hide", "render"]
