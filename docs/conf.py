"""Sphinx configuration of the torchrl-cebp docs: ``bash scripts/build_docs.sh`` builds them, warnings as errors."""
import inspect
import os
import re
import shutil
from pathlib import Path
from urllib.parse import unquote

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
# package-index.md is the package's page on the package index (pyproject's readme), not a page of this site.
exclude_patterns = ["_build", "package-index.md"]

myst_heading_anchors = 3  # links to a page's section, as on GitHub: [text](training.md#checkpoints-and-resume)
myst_enable_extensions = ["colon_fence"]

# undoc-members: a public member without a docstring still gets its entry, which then fails the build
# (flag_undocumented) rather than silently missing from the reference. The inherited members shown are those of
# private bases only (show_private_bases_members).
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
PACKAGE = "torchrl_cebp"
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


def is_private_class(cls: type) -> bool:
    """Whether the reference leaves ``cls`` out: a private name, or a class of one of this package's private
    modules (``torchrl_cebp._upstream``)."""
    parts = cls.__qualname__.split(".")
    if cls.__module__.partition(".")[0] == PACKAGE:
        parts += cls.__module__.split(".")
    return any(part.startswith("_") for part in parts)


def public_bases(bases: list[type]) -> list[type]:
    """``bases`` with each private one replaced by its own public bases (``object`` only where nothing else is)."""
    public = []
    for base in bases:
        for candidate in public_bases(list(base.__bases__)) if is_private_class(base) else [base]:
            if candidate not in public:
                public.append(candidate)
    return [base for base in public if base is not object] or public


def hide_private_bases(app, name, obj, options, bases) -> None:
    """The "Bases:" line names the classes a reader can look up: a private base (``_ContactEnergySampler``) gives
    way to its public ones, and its members are shown as the subclass's own (show_private_bases_members)."""
    bases[:] = public_bases(bases)


def show_private_bases_members(app, what, name, obj, options, lines) -> None:
    """A class's entry shows the public members it takes from a private base of this package (``EpisodeStorage``'s
    ``valid_lengths``, from ``_EpisodeRows``) as its own, after its docstring: the base has no entry to show them.
    Members of public bases stay on their own classes' entries, or in TorchRL's docs."""
    if what not in ("class", "exception") or not inspect.isclass(obj):
        return
    for base in obj.__mro__[1:]:
        if not is_private_class(base) or base.__module__.partition(".")[0] != PACKAGE:
            continue
        for member_name, value in vars(base).items():
            if member_name.startswith("_") or next(cls for cls in obj.__mro__ if member_name in vars(cls)) is not base:
                continue  # private, or overridden below the base
            if is_attribute(obj, member_name, value) and described_in_docstring(obj, member_name):
                continue  # as skip_described_attributes
            if isinstance(value, property):
                directive = "autoproperty"
            elif inspect.isroutine(value) or isinstance(value, (classmethod, staticmethod)):
                directive = "automethod"
            else:
                directive = "autoattribute"
            lines += ["", f".. {directive}:: {name}.{member_name}"]


def class_being_documented(env) -> type | None:
    """The class whose members autodoc is choosing now (``autodoc-skip-member`` is not told)."""
    import importlib

    document = getattr(env, "current_document", None)
    if document is not None:
        module_name, class_name = document.autodoc_module, document.autodoc_class
    else:  # Sphinx < 8.2
        module_name, class_name = env.temp_data.get("autodoc:module"), env.temp_data.get("autodoc:class")
    if not module_name or not class_name:
        return None
    value = importlib.import_module(module_name)
    for part in class_name.split("."):
        value = getattr(value, part, None)
    return value if inspect.isclass(value) else None


def is_attribute(cls: type, name: str, value: object) -> bool:
    """Whether member ``name`` of ``cls`` is data: a dataclass's or named tuple's field, an enum's member, or a class or
    instance attribute, not a method or property."""
    import dataclasses

    if dataclasses.is_dataclass(cls) and name in {field.name for field in dataclasses.fields(cls)}:
        return True
    if name in getattr(cls, "_fields", ()):
        return True
    return not (inspect.isroutine(value) or isinstance(value, (property, classmethod, staticmethod, type)))


def described_in_docstring(cls: type, name: str) -> bool:
    """Whether the docstring of ``cls`` describes ``name``: an ``Args:`` entry (``name (type): ...``, or ``a, name: as
    for ...``) or the name in double backquotes."""
    entry = rf"^\s*(?:\w+, )*{re.escape(name)}(?:, \w+)*(?: \(|:)"
    return bool(re.search(rf"{entry}|``{re.escape(name)}``", cls.__doc__ or "", re.MULTILINE))


def skip_described_attributes(app, what, name, obj, skip, options) -> bool | None:
    """An attribute (a dataclass's field, an enum's member) that its class's docstring describes gets no entry of its
    own to say it again. One the docstring does not describe keeps its entry, and fails the build if it has no
    docstring either (flag_undocumented)."""
    if what not in ("class", "exception") or skip:
        return None
    cls = class_being_documented(app.env)
    if cls is not None and is_attribute(cls, name, obj) and described_in_docstring(cls, name):
        return True
    return None


def has_description(content: addnodes.desc_content) -> bool:
    """Whether an entry says anything besides what autodoc writes by itself: its "Bases:" line, "alias of", the
    type hints' field lists and the entries of its members."""
    for position, child in enumerate(content.children):
        if isinstance(child, (addnodes.desc, addnodes.index, nodes.field_list)):
            continue
        if isinstance(child, nodes.paragraph) and (
            position == 0 and child.astext().startswith("Bases: ") or child.astext().startswith("alias of ")
        ):
            continue
        return True
    return False


def flag_undocumented(app, domain, objtype, content) -> None:
    """The API reference's other promise: every public entry it shows says what it is. A public class, function,
    method, property, attribute or constant without a docstring (or, for a constant, the API page's text) fails
    the build."""
    if domain != "py":
        return
    for signature in content.parent.findall(addnodes.desc_signature):
        if signature.parent is not content.parent:
            continue
        name = f"{signature['module']}.{signature['fullname']}"
        if not any(part.startswith("_") for part in name.split(".")) and not has_description(content):
            logger.warning(f"{name} is shown in the API reference but has no docstring", type="api",
                           location=content.parent)


def anchor_viewcode_backlinks(app, doctree) -> None:
    """viewcode's "[docs]" link from a source module's code goes to ``page#<path>.<name>``, where ``<path>`` is the
    package the first documented object of that source module was shown under. An object re-exported by another
    package (``torchrl_cebp.sim2real.Workspace``, of ``torchrl_cebp.envs.franka``) gets that anchor too."""
    from sphinx.ext.viewcode import OUTPUT_DIRNAME, viewcode_anchor

    source_modules = getattr(app.env, "_viewcode_modules", {})
    for anchor in doctree.findall(viewcode_anchor):
        signature = anchor.parent
        entry = source_modules.get(anchor["reftarget"].removeprefix(f"{OUTPUT_DIRNAME}/").replace("/", "."))
        if not entry or entry[3] == signature["module"]:
            continue
        alias = f"{entry[3]}.{signature['fullname']}"
        if alias not in signature["ids"]:
            signature["ids"].append(alias)


LINK = re.compile(r'href="([^"#]*)#([^"]+)"')
ID = re.compile(r'\bid="([^"]+)"')


def check_anchors(app, exception) -> None:
    """A link of the built site to an anchor its target page lacks fails the build (a broken link already does)."""
    if exception is not None or app.builder.format != "html":
        return
    outdir = Path(app.outdir).resolve()
    ids: dict[Path, set[str]] = {}

    def ids_of(page: Path) -> set[str]:
        if page not in ids:
            ids[page] = set(ID.findall(page.read_text(encoding="utf-8"))) if page.is_file() else set()
        return ids[page]

    for page in outdir.rglob("*.html"):
        if "_static" in page.relative_to(outdir).parts:
            continue
        for target, anchor in set(LINK.findall(page.read_text(encoding="utf-8"))):
            if target and (":" in target or target.startswith("//") or not target.endswith(".html")):
                continue  # another site, or a data file
            target_page = (page.parent / unquote(target)).resolve() if target else page
            if unquote(anchor) not in ids_of(target_page):
                logger.warning(f"{page.relative_to(outdir)} links to {target or page.name}#{anchor}, an anchor that "
                               "page lacks", type="anchor")


def drop_type_docstrings(app, what, name, obj, options, lines) -> None:
    """A constant has no docstring of its own, and autodoc would show its type's (``tuple``'s, a class's). The API
    pages describe each constant instead."""
    type_doc = (type(obj).__doc__ or "").strip()
    if what == "data" and lines and type_doc and lines[0].strip() == type_doc.splitlines()[0].strip():
        lines.clear()


def init_signature(app, what, name, obj, options, signature, return_annotation):
    """TorchRL's samplers have a metaclass whose ``__call__`` takes ``(*args, **kwargs)``, which autodoc would show as
    every sampler's signature: show the constructor's instead."""
    if what == "class" and signature == "(*args, **kwargs)":
        parameters = list(inspect.signature(obj.__init__).parameters.values())[1:]
        return str(inspect.Signature(parameters)), return_annotation
    return None


def setup(app):
    app.connect("autodoc-process-signature", init_signature)
    app.connect("autodoc-process-bases", hide_private_bases)
    app.add_post_transform(LinkToData)
    app.connect("autodoc-process-docstring", drop_type_docstrings)
    app.connect("autodoc-process-docstring", show_private_bases_members, priority=600)  # after napoleon's
    app.connect("autodoc-skip-member", skip_described_attributes)
    app.connect("object-description-transform", flag_undocumented)
    app.connect("doctree-read", anchor_viewcode_backlinks, priority=600)  # after viewcode's own
    app.connect("env-check-consistency", check_api_reference)
    app.connect("build-finished", copy_data)
    app.connect("build-finished", check_anchors, priority=600)  # after the data folders are copied
