"""softcath_ros: model, steering and bench characterisation of a soft fluidic catheter."""

__version__ = "0.1.0"
