"""The mobility problem and its solver: default physics (pair laws), user hooks, the System, the saddle-point solve."""
