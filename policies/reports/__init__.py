"""Comparison reports: trained runs beside the scripted baselines (markdown, figures) and sweep tables."""
