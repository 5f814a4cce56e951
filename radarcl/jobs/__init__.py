"""What the CLI runs: the main job (demo, Fig. 9), fusing a recording, the Navtech map and report,
and the figures they draw. Library code lives one level up; nothing below imports from here."""
