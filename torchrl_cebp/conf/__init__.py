"""The Hydra training configs (config.yaml and its groups): a package, so that Hydra finds them in an installed copy."""
