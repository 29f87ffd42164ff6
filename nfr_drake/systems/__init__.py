"""Drake systems and diagram builders: the robot, keypoint sources, simulation, replays, perception."""
