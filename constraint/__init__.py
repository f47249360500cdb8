"""Published import path ``constraint.constraint`` (a face for users' override files; the package never imports it)."""
