"""Studies: experiments that combine the stages (generate, train, benchmark) to answer one question.

:mod:`.data_value` measures what the generator's scenes are worth to a learned denoiser on scenes
someone else built. A study is a top layer: it may import every stage, and no stage imports it.
"""
