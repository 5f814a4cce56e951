"""Judging maps: truth that says what a radar can know (``visibility``), the metrics on it
(``metrics``), the baselines (``baseline``), recorded observations mapped by a configuration and
scored (``evaluate``: it builds the pipelines it judges), error against run time (``quality``),
held-out detections on real scans (``heldout``), the tuning search and the calibration fit."""
