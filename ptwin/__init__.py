"""ptwin: hybrid twins of AFM nanoindentation that tell what physics a model left out."""

from ptwin.physics.fluid_force import FluidForce

__all__ = ["FluidForce"]
