"""Rigid-body dynamics of a ship in the horizontal plane: the equations of motion
(`equations`: mass matrix, kinematics, differentiable integration with torchdiffeq) and the
fixed-step integrator choice (`integrators`)."""
