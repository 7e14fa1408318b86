"""Prior files (JSON). Installed as the package ``bayesrod.priors``; see docs/priors.md."""
