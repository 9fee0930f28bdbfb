"""Source text shared by the hostile plugin modules of the sandbox tests (denoisers and samplers).

``SOURCE`` defines, inside a plugin module, ``_routes()`` (the folders where a plain worker process
would find the dataset: the path it was told, its parent's ``--data`` argument, the parent's working
folder, ``$HOSTILE_DATA``), ``_snoop()`` (opens every reference EXR found there and the one it was
told; raises ``LEAK: ...`` on the first it reads, else ``contained: ...``) and ``_vandalise(attempts)``
(runs each ``(what, write)``; raises ``VANDALISED: ...`` if one succeeds, else ``contained: ...`` with
each refusal). It is inserted into a module's template as a ``str.format`` value, so it is written
with single braces; the module must ``import glob, os`` and define ``DATASET`` and ``REFERENCE``.
"""

SOURCE = '''
def _routes():
    """Folders where a plain worker finds the dataset: its parent's argv, cwd, the environment."""
    found = [DATASET]
    try:
        argv = open(f"/proc/{os.getppid()}/cmdline", "rb").read().split(b"\\0")
        found += [a.decode() for prev, a in zip(argv, argv[1:]) if prev == b"--data"]
    except OSError:
        pass
    try:
        found.append(os.readlink(f"/proc/{os.getppid()}/cwd"))
    except OSError:
        pass
    found += [v for k, v in os.environ.items() if k == "HOSTILE_DATA"]
    return found


def _snoop():
    tried = []
    for folder in _routes():
        for path in glob.glob(os.path.join(folder, "*", "reference", "*.exr")) + [REFERENCE]:
            try:
                with open(path, "rb") as handle:
                    handle.read(16)
                raise RuntimeError(f"LEAK: read {path}")
            except OSError as error:
                tried.append(type(error).__name__)
    raise RuntimeError(f"contained: no reference in reach ({len(tried)} tries)")


def _vandalise(attempts):
    done, refused = [], []
    for what, attempt in attempts:
        try:
            attempt()
            done.append(what)
        except OSError as error:
            refused.append(f"{what}: {error.strerror}")
    if done:
        raise RuntimeError(f"VANDALISED: {done}")
    raise RuntimeError(f"contained: {'; '.join(refused)}")
'''
