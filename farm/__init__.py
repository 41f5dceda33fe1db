"""treefarm: farm."""
