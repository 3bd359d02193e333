"""Localization: MCL (Nav2 AMCL's model) and the RBPF with door states of paper 000, Sec. IV."""
