"""Pedestrian-vehicle conflicts from any SUMO FCD output (`python -m pedsafe_sumo.conflicts`).

`read_fcd` streams the timesteps, `InteractionTracker` cuts them into vehicle-person interactions and
measures each with `pedsafe_sumo.safety.interaction` (the batch's own index functions). docs/conflicts.md
describes the columns, the SSM-like XML and the choices.
"""
