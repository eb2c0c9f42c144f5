"""The science of beyond-self as a plain library: no bus, usable offline from a notebook.

Affordance–Words Bayesian network, gesture HMMs, their fusion, verbal descriptions, and the
vision front end that turns camera frames into the network's discrete variables.
"""
