"""Simulation with exact truth: the FMCW beat-signal simulator (``fmcw``), scenes of solids
(``shapes``, ``outdoor``: the paper's reference scene; ``generator``: random streets and fields),
the radar observing them (``observe``), and range profiles of simple echoes (``echoes``,
``resolution``)."""
