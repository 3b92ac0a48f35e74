"""Demand: background vehicles and pedestrians drawn from the fitted distributions, as SUMO routes."""
