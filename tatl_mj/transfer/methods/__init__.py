"""The built-in transfer methods, one module per family.

- :mod:`.tatl`: ``ta-tl``, the paper's rule (Algorithms 1 and 2).
- :mod:`.target_fqi`: target FQI and the methods built on it (``uma-tl``,
  ``uma-tl-prior``, ``rl`` and their data-protocol variants).
- :mod:`.horizon`: ``ta-tl-h`` and its ablations (horizon-matched TA-TL), with its
  policy in :mod:`.horizon_policy` and the oracle's model in :mod:`.linearisation`.
- :mod:`.replan`: ``ta-tl-replan`` and ``ta-tl-oracle`` (discrete targets).
- :mod:`.model_based`: ``apprentice-fqi``, TA-TL's apprentice without the source.
- :mod:`.projected`: ``projected-source``, the mapped source policy as a reference.

``tatl_mj.transfer.registry`` names them; the contract they follow is
``tatl_mj.transfer.method``.
"""
