"""Sphinx configuration of the torchrl-cebp docs: ``bash scripts/build_docs.sh`` builds them, warnings as errors."""
import os
import shutil
from pathlib import Path

from docutils import nodes
from sphinx import addnodes
from sphinx.transforms.post_transforms import SphinxPostTransform
from sphinx.util import logging

logger = logging.getLogger(__name__)

os.environ.setdefault("MUJOCO_GL", "osmesa")  # autodoc imports the Sim2Real twin, which renders offscreen

project = "torchrl-cebp"
author = "torchrl-cebp contributors"
copyright = "torchrl-cebp contributors, MIT licence"

extensions = [
    "sphinx.ext.autodoc",  # the API reference, from the docstrings
    "sphinx.ext.napoleon",  # their Google form (Args:, Returns:, Examples:), as TorchRL's
    "sphinx.ext.viewcode",
    "myst_parser",  # the Markdown pages
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# The pages; results/, benchmarks/ and img/ otherwise hold data, figures and raw outputs that the pages show or link.
include_patterns = ["*.md", "api/*", "results/sim2real/diagnosis.md"]
exclude_patterns = ["_build"]

myst_heading_anchors = 3  # links to a page's section, as on GitHub: [text](training.md#checkpoints-and-resume)
myst_enable_extensions = ["colon_fence"]

autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
# Methods that override TorchRL's would otherwise carry TorchRL's own docstrings, written for TorchRL's site.
autodoc_inherit_docstrings = False
napoleon_google_docstring = True
napoleon_numpy_docstring = False

html_theme = "furo"
html_title = "torchrl-cebp"


# The pages link to the data behind them (CSVs, run folders, raw benchmark output), as they do on GitHub.
DOCS = Path(__file__).resolve().parent
DATA_FOLDERS = ("results", "benchmarks", "img")


class LinkToData(SphinxPostTransform):
    """A Markdown link to a file or folder under ``docs/`` that is not a page links to its copy in the site.

    It runs just before MyST's resolver (priority 9), which would otherwise report the link as broken. A link to a
    path that does not exist is left to MyST, and fails the build.
    """

    default_priority = 8

    def run(self, **kwargs) -> None:
        for node in list(self.document.findall(addnodes.pending_xref)):
            if node["reftype"] != "myst":
                continue
            target = node["reftarget"]
            if node["refdomain"] == "doc":  # a link to a Markdown file that is data, not a page
                target += ".md"
            page_folder = (DOCS / node.get("refdoc", self.env.docname)).parent
            path = (page_folder / target).resolve()
            if path.is_relative_to(DOCS) and path.exists() and path.parts[len(DOCS.parts)] in DATA_FOLDERS:
                link = nodes.reference("", "", internal=False, refuri=target)
                link += node[0].deepcopy()
                node.replace_self(link)


def copy_data(app, exception) -> None:
    if exception is None and app.builder.format == "html":
        for folder in DATA_FOLDERS:
            shutil.copytree(DOCS / folder, Path(app.outdir) / folder, dirs_exist_ok=True)


# The API reference's promise: an entry for every public name. A name added to a package's ``__all__`` (or a public
# function or class of a module without one) and missing from docs/api/ fails the build.
API_MODULES = (
    "torchrl_cebp.envs",
    "torchrl_cebp.replay",
    "torchrl_cebp.replay.samplers",
    "torchrl_cebp.agents",
    "torchrl_cebp.training",
    "torchrl_cebp.sim2real",
    "torchrl_cebp.stats",
    "torchrl_cebp.plot",
)


def public_names(module_name: str) -> list[str]:
    import importlib
    import inspect

    module = importlib.import_module(module_name)
    if hasattr(module, "__all__"):
        return list(module.__all__)
    return [
        name
        for name, value in vars(module).items()
        if not name.startswith("_")
        and (inspect.isclass(value) or inspect.isfunction(value))
        and value.__module__ == module_name
    ]


def check_api_reference(app, env) -> None:
    documented = set(env.get_domain("py").objects)
    for module_name in API_MODULES:
        for name in public_names(module_name):
            if f"{module_name}.{name}" not in documented:
                logger.warning(f"{module_name}.{name} is public but has no entry in docs/api/", type="api")


def drop_type_docstrings(app, what, name, obj, options, lines) -> None:
    """A constant has no docstring of its own, and autodoc would show its type's (``tuple``'s, a class's). The API
    pages describe each constant instead."""
    type_doc = (type(obj).__doc__ or "").strip()
    if what == "data" and lines and type_doc and lines[0].strip() == type_doc.splitlines()[0].strip():
        lines.clear()


def init_signature(app, what, name, obj, options, signature, return_annotation):
    """TorchRL's samplers have a metaclass whose ``__call__`` takes ``(*args, **kwargs)``, which autodoc would show as
    every sampler's signature: show the constructor's instead."""
    import inspect

    if what == "class" and signature == "(*args, **kwargs)":
        parameters = list(inspect.signature(obj.__init__).parameters.values())[1:]
        return str(inspect.Signature(parameters)), return_annotation
    return None


def setup(app):
    app.connect("autodoc-process-signature", init_signature)
    app.add_post_transform(LinkToData)
    app.connect("autodoc-process-docstring", drop_type_docstrings)
    app.connect("env-check-consistency", check_api_reference)
    app.connect("build-finished", copy_data)
