"""Evaluation: quality figures of a prediction (``metrics``), the ink set's colour -> mixture table
(``colour_table``), print-shop baselines (``baselines``) and the ``inkopt evaluate`` stage (``evaluate``)."""
