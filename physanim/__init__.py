"""physanim: physically based animation from performance capture."""

__version__ = "0.1.0"
