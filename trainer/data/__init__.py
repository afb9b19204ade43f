"""Mocap -> canonical pose dataset: BVH reading, joint maps, the builder and the loader.

Modules:

- :mod:`core.bvh` (shared with the service): BVH parser and batched forward kinematics.
- :mod:`trainer.data.asf`: Acclaim ASF/AMC reader (CMU subjects) with the same interface.
- :mod:`trainer.data.maps`: per-source joint maps (``trainer/maps/*.toml``).
- :mod:`trainer.data.build`: ``pose-trainer dataset`` (archives -> ``poses.npz``); its
  checks (:mod:`trainer.data.checks`), summary (:mod:`trainer.data.summary`) and splits
  (:mod:`trainer.data.splits`).
- :mod:`trainer.data.dataset`: ``load_dataset`` / ``PoseDataset`` and the file format.
- :mod:`trainer.data.plot`: ``pose-trainer plot-data`` (stick figures of random poses).
"""
