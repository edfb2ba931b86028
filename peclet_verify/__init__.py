"""peclet_verify: Hypothesis strategies, certification properties and the pytest plugin."""
