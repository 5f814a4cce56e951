"""Readers, writers and streams of radar data and files. No pyopencl imports here.

``inputs.open_input`` opens any sensor's recordings and scans; ``files`` reads and writes files
safely; ``recording``, ``polar_png``, ``ti_adc`` read formats; ``stream``, ``beam_protocol``,
``ti_uart``, ``emulator`` and ``brick_stream`` carry live streams.
"""
