"""Seeing a new object: fitting z to posed images, forward simulation of its motion, reports."""
