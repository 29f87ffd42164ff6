"""The paper's image-encoder baseline (ResNet-style encoder over posed views)."""
