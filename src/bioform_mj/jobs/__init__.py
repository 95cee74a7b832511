"""Many runs: the job runner, sweeps, calibration, Ray, provenance, Table I and the CPU benchmark (design §7, §16)."""
