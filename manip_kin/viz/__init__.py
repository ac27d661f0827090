"""Pictures for a person: figures of a recorded run, animations, sweeps, markers and the live view's feed."""
