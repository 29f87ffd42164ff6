"""Planning from keypoint trajectories: grasp frames, base placement, trajectory optimisation."""
