"""How a scenario is solved: steps, schedule graphs, the compiler, the executor and the CLI."""
__all__: list[str] = []
