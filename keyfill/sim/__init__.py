"""Physics-based hopping-lamp ("Luxo") dataset: pybullet model, PD control, annealing search."""
