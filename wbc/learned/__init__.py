"""The learned contender, split at the torch line.

`wbc.learned.policy` runs exported policies in numpy (shipped, no torch); `wbc.learned.env` is the batched MuJoCo
training env (numpy); `wbc.learned.train` holds the staged PPO + BC procedure, RMA and the export, whose modules
that need torch import it through the ``train`` extra. The shipped weights are in ``weights/``.
"""
