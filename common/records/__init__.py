"""What a run leaves behind: recorder, recordings, traces, histograms, cut figures and the
height-map codec."""
