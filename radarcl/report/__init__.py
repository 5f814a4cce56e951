"""What people read: figures (``figures``, every one checked for overlaps and cut-off labels),
HTML pages (``html``), and the error-against-run-time tables (``quality``)."""
