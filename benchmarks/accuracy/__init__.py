"""What starnav gets right: simulated star lists and frames, scored against the truth."""
