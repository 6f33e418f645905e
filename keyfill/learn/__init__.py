"""Learned and baseline in-betweening: datasets, models, training, metrics, baselines."""
