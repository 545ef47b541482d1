"""PointNet + MLP surrogate of grasp outcomes (to come; nothing is implemented yet)."""
