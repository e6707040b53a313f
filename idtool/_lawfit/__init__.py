"""``idtool fit-law``: a friction law fitted to a velocity-force series (issue 30)."""
