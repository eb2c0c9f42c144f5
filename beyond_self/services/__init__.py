"""Thin asyncio services: each subscribes, calls the `cognition` library, and publishes."""
