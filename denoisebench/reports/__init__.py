"""Reports of one run: the model of everything shown (``model``), built from ``analysis`` and
``results`` (``build``: report.md, index.html, results.json, results.csv, figures), Markdown and HTML
writers, figures, images, strips and sentences. Runs nothing: the hard-case table comes in built.
"""
