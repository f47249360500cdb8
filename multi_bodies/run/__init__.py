"""A run: set-up shared by every script, run output (snapshots, .info, restart records), the time loop, VTK and velocity-field output."""
