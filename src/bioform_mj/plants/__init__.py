"""Plants the control stack drives: the paper's ideal model and MuJoCo robots."""
