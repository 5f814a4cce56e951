"""One plan object per kernel file: an expensive constructor, a cheap checked call."""
