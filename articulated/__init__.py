"""Published import path ``articulated.articulated`` (a face for users' override files; the package never imports
it)."""
