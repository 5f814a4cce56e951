"""What the commands run: the main job (demo, Fig. 9), fusing any input (``fuse``, ``fuse_many``),
the Navtech map and report, calibration, the live loop. Library code lives below; nothing
below imports from here."""
