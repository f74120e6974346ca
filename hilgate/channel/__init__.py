"""A channel that knows the water: BELLHOP run as a separate program, its files read with our own readers,
its fields cached on disk (``runner.py``); the lookups themselves are pure (``hilgate.models.bellhop_fields``)."""
