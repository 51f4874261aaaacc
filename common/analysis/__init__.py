"""Stability analysis of the teleoperation loop: the paper's small-gain condition (eq 30) and
exact stability under a round-trip network delay (Nyquist / argument principle with the exact
e^(-j w tau)), delay margins and the largest stable gains, continuous or sampled at Ts."""
