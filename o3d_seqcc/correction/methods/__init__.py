"""The correction methods (Table 1 and beyond), one module per published method or family.

- :mod:`~o3d_seqcc.correction.methods.seqcc`: ``seqcc`` (the paper's), ``seqcc-joint``;
- :mod:`~o3d_seqcc.correction.methods.seqcc_global`: ``seqcc-global`` (the default);
- :mod:`~o3d_seqcc.correction.methods.edge_summaries`, :mod:`~o3d_seqcc.correction.methods.joint_curves`:
  its parts (every edge as matched quantiles; per-view curves over all edges);
- :mod:`~o3d_seqcc.correction.methods.pairwise`: ``none``, ``reinhard``, ``root-polynomial``, ``vandermonde``;
- :mod:`~o3d_seqcc.correction.methods.global_methods`: ``gain-compensation``, ``histogram-matching``.
"""
