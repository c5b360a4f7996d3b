"""Rigid-body dynamics of a ship in the horizontal plane: the equations of motion
(`equations`: mass matrix, kinematics, differentiable integration: Euler's own loop, torchdiffeq's rk4) and the
fixed-step integrator choice (`integrators`)."""
