"""Generated dynamics of the shipped robots (tools/generate_models.py); do not edit."""
