"""treefarm: trainers."""
