"""The learned models' names, importable without torch: what ``denoisebench train --model`` and
``denoisebench study --models`` offer. :data:`denoisebench.models.catalog.MODELS` builds each, in this
order, and refuses to import when the two disagree.
"""

MODEL_NAMES = ("dpcn", "kpcn", "rae", "lbf")
