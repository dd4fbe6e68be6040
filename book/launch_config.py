"""The book's configuration, with launch buttons when the repository's address is known.

Jupyter Book draws a "launch on Binder" button on every chapter only when its configuration names
the repository, and nothing in a clone knows where it was published. So ``book/_config.yml`` builds
an offline book without buttons, and ``book/build.sh`` runs this script first:

    RACING_LAB_REPOSITORY=https://github.com/<owner>/<repo> book/build.sh

With the variable set, the script writes ``book/_config.launch.yml`` (beside the original, so that
its relative paths still hold; git ignores it): the same configuration plus
the repository, its branch (``RACING_LAB_BRANCH``, default ``main``) and mybinder.org as the
BinderHub (``RACING_LAB_BINDERHUB`` to use another), and prints its path. Without the variable it
prints the path of ``book/_config.yml`` unchanged. Binder builds the image from ``binder/``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import yaml

BOOK = Path(__file__).resolve().parent
MYBINDER = "https://mybinder.org"


def launch_config(
    base: dict, repository: str, branch: str = "main", binderhub: str = MYBINDER
) -> dict:
    """``base`` (a parsed ``_config.yml``) with launch buttons for ``repository``.

    Parameters
    ----------
    base : dict
        The book's configuration.
    repository : str
        The repository's web address, ``https://github.com/<owner>/<repo>``.
    branch : str
        The branch the buttons open.
    binderhub : str
        The BinderHub that builds and serves the notebooks.

    Returns
    -------
    dict
        A copy of ``base``; ``base`` itself is not changed.
    """
    if not repository.startswith(("https://", "http://")):
        raise ValueError(
            f"RACING_LAB_REPOSITORY must be a web address such as "
            f"https://github.com/<owner>/<repo>, not {repository!r}"
        )
    config = yaml.safe_load(yaml.safe_dump(base))
    config["repository"] = {"url": repository.rstrip("/"), "branch": branch, "path_to_book": ""}
    config.setdefault("html", {})["use_repository_button"] = True
    config.setdefault("launch_buttons", {})["binderhub_url"] = binderhub
    return config


def main() -> int:
    """Print the configuration file book/build.sh should pass to jupyter-book."""
    source = BOOK / "_config.yml"
    repository = os.environ.get("RACING_LAB_REPOSITORY", "").strip()
    if not repository:
        print(source)
        return 0
    base = yaml.safe_load(source.read_text())
    try:
        config = launch_config(
            base,
            repository,
            branch=os.environ.get("RACING_LAB_BRANCH", "main"),
            binderhub=os.environ.get("RACING_LAB_BINDERHUB", MYBINDER),
        )
    except ValueError as err:
        print(f"book/launch_config.py: {err}", file=sys.stderr)
        return 2
    target = BOOK / "_config.launch.yml"
    target.write_text(yaml.safe_dump(config, sort_keys=False))
    print(target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
