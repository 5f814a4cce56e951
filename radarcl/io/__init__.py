"""Frame formats, recordings and readers of other radars' files. No pyopencl imports here."""
