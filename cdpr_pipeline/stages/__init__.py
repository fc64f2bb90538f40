"""Task functions behind the ``cdpr`` subcommands.

Each module has a plain function taking a composed config (tests call it directly) and a
thin ``@hydra.main`` wrapper ``main`` that the CLI dispatches to.
"""
