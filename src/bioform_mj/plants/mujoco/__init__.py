"""The MuJoCo plant: the plant class, its compiled kernels and its in-loop contact watch (design §8, §19)."""
