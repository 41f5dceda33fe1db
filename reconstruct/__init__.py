"""treefarm: reconstruct."""
