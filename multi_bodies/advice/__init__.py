"""The advisor: measurements on the user's scene, the cost and error models, the report."""
