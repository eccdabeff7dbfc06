"""Joint trajectories for the robot: kinematics, inverse kinematics, limits, collisions, timing.

``motion`` never imports ``sim`` or pybullet: the Panda's kinematics are read from its URDF with
ElementTree and evaluated in numpy, so a trajectory can be planned for a real cell.
"""
