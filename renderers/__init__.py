"""treefarm: renderers."""
