"""sharp_ref: axisymmetric sharp-interface membranes, an independent reference."""
