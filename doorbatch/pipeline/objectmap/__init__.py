"""Object maps of walls and doors learned with EM (paper 001): shape, colour and motion."""

from doorbatch.pipeline.objectmap.model import ClassParams, Door, ObjectMap, Wall

__all__ = ["ClassParams", "Door", "ObjectMap", "Wall"]
