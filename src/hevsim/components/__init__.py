"""Component physics: pure, vectorised, SI.

Each physics function is written once with numpy ufuncs and arithmetic only (no branches on
values), compiled with numba, and therefore accepts scalars inside compiled simulation loops
and numpy arrays of any (broadcast) shape from Python (quasi-static and DP models).
"""
