"""The robot's eyes: camera frames in, the network's object and effect variables out (README.md)."""
