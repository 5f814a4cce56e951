"""Judging maps, never building them: ground-truth metrics, the OctoMap-style baseline, running
recorded observations through a configuration and scoring it, and the documented tuning search."""
