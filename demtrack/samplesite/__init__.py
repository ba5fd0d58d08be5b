"""The Bushy-Run-like sample site: a deterministic synthetic world and its generator."""
