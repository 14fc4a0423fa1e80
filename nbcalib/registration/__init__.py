"""Fine registration (paper section III-E): NID cost, hidden-point removal, optimisers."""
