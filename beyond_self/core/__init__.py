"""The bottom layer: what every other package of ours may import (it imports none of them).

`schemas/` (the messages) and `cognition/` (the science) both raise the one input-error type, and
neither may depend on the other, so it lives here.
"""
