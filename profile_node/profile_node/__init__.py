"""Target curve: jerk-limited, time-parameterised reference built from a line description."""
