"""Old home of `bench_train`, kept only while a caller still imports it from here: use `wbc.tools.bench`.

The one remaining caller is tests/test_learned.py (``from wbc.tools.bench_train import bench_train``); delete this
module once it imports ``from wbc.tools.bench import bench_train``.
"""

from wbc.tools.bench import TRAIN_TARGET, bench_train

__all__ = ["TRAIN_TARGET", "bench_train"]
