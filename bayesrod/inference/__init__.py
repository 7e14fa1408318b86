"""Priors, likelihood, sampler, summaries and the deterministic two-stage estimate."""
