"""Rendering with Drake, dataset shards, capture sets."""
