"""The mobility problem and its solver: default physics (pair laws), user hooks, the frozen Model, the problems and their one solve."""
