"""Foxglove: the live WebSocket bridge, its layout and the derived views."""
