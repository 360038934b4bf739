"""The perception maths: NumPy arrays in, small typed results out. No Zenoh, MuJoCo or MCAP."""
