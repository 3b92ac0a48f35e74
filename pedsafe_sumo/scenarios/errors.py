"""The error every scenario module raises for a scenario that cannot be specified or staged."""


class ScenarioError(ValueError):
    """Unknown scenario, unknown parameter, or a parameter out of range."""
