"""What planning, simulation and replays share: the robot model, keypoint trajectories, obstacle
boxes and planned motions. Values and model loaders only; nothing here plans or simulates."""
