"""Hybrid tracker of Zhang, Brunnett & Rusdorf 2011: markers on head and hands plus one camera."""
