"""Controls every editing widget shares: undo/redo/reset buttons and BVH export.

The buttons only forward: ``undo``, ``redo`` and ``reset`` are the editor's
methods (its :class:`mocaplab.undo.UndoStack` does the work); export writes
the editor's current motions with :func:`mocaplab.io.save_bvh`.  A widget
calls :meth:`HistoryButtons.sync` after every change so a button is enabled
exactly when its action is possible.
"""

from __future__ import annotations

import html
import os
import re
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import anywidget
import ipywidgets as W
import traitlets

from mocaplab.io import save_bvh
from mocaplab.motion import Motion

__all__ = [
    "HistoryButtons", "ExportControl", "export_paths", "error_html", "ERROR_STYLE", "MAX_ERROR_TEXT", "row", "keep_width",
    "export_name", "free_paths", "history_status", "Shortcut", "bind_keys", "viewer_shortcuts", "KeyCapture",
    "keys_help",
]

#: Widgets kept at their own width in a :func:`row`: controls (a squeezed one reads "..."), pictures and boxes.
_FIXED = (
    W.Button,
    W.ToggleButton,
    W.Checkbox,
    W.Dropdown,
    W.Text,
    W.BoundedFloatText,
    W.Select,
    W.Label,
    W.FloatSlider,
    W.IntSlider,
    W.Image,
    W.Box,
)


def keep_width(*widgets: W.Widget) -> None:
    """Never let a flex row shrink these widgets below their own width (``flex: 0 0 auto``).

    A widget whose layout already says how it flexes (a slider that may
    grow) is left as it is.
    """
    for widget in widgets:
        if not widget.layout.flex:
            widget.layout.flex = "0 0 auto"


def row(children: Sequence[W.Widget], *, align: str = "center") -> W.HBox:
    """A row that wraps onto the next line when the notebook is too narrow, instead of squeezing or overflowing.

    Controls (buttons, toggles, boxes, sliders) keep their width
    (:func:`keep_width`); text (HTML, labels) takes what is left and wraps;
    boxes keep their width and move to the next line as a whole (a 3D view
    drops below the plot when there is no room beside it).

    Parameters
    ----------
    children : sequence of ipywidgets.Widget
    align : str
        CSS ``align-items`` of the row.

    Returns
    -------
    ipywidgets.HBox
        ``flex-flow: row wrap``; also the class ``mocaplab-row``.

    Examples
    --------
    >>> import ipywidgets as W
    >>> r = row([W.Button(description="step"), W.HTML("mean 3 mm")])
    >>> r.layout.flex_flow, r.children[0].layout.flex
    ('row wrap', '0 0 auto')
    """
    for child in children:
        if isinstance(child, _FIXED):
            keep_width(child)
        elif not child.layout.flex:
            child.layout.flex = "1 1 auto"
            child.layout.min_width = child.layout.min_width or "120px"
    box = W.HBox(list(children), layout=W.Layout(flex_flow="row wrap", align_items=align))
    box.add_class("mocaplab-row")
    return box


#: Most characters of an error's text a status line shows; the rest is counted, not shown (a message of a
#: megabyte would make the page slow to draw and is not read).
MAX_ERROR_TEXT = 20_000

#: How an error looks when the caller does not say: dark red, wrapped at the box's width, every line kept.
ERROR_STYLE = "color:#b00; white-space:pre-wrap; overflow-wrap:anywhere; margin:0"


def _text(get: Callable[[], object], what: str) -> str:
    """``get()`` as plain text (a ``str`` subclass with its own methods is copied out); never raises."""
    try:
        value = get()
        return str.__str__(value) if isinstance(value, str) else str.__str__(str(value))
    except Exception:  # noqa: BLE001 - an error display must not fail
        return f"<{what} could not be shown>"


def _where(err: BaseException) -> str:
    """`` (function, line N)`` of the innermost frame of ``err``'s traceback, or ``""``."""
    try:
        frames = traceback.extract_tb(err.__traceback__) if err.__traceback__ is not None else []
        return f" ({frames[-1].name}, line {frames[-1].lineno})" if frames else ""
    except Exception:  # noqa: BLE001 - an error display must not fail
        return ""


def error_html(
    err: BaseException, *, trace: bool = False, where: bool = False, tag: str = "pre", style: str = ERROR_STYLE
) -> str:
    """An exception as the HTML of a widget's status line; never raises.

    The one error display of the widgets (the editors, the touch-up, the
    staggered explorer, the 3D viewer).  The message of an exception is user
    code (``__str__``) and may itself fail, not be text, hold markup or be
    megabytes long: the display shows the type and what it can of the
    message, HTML-escaped, at most :data:`MAX_ERROR_TEXT` characters (the
    rest counted), and never lets a second exception out of the widget's
    callback.

    Parameters
    ----------
    err : BaseException
    trace : bool
        Add the last frames of the traceback.
    where : bool
        Add `` (function, line N)`` of the frame that raised.
    tag : {"pre", "span"}
        The element: a ``<pre>`` block, or a ``<span>`` inside a line of text.
    style : str
        Its CSS (escaped as an attribute); default :data:`ERROR_STYLE`.

    Returns
    -------
    str
        ``<tag class='mocaplab-error' style='...'>Type: message</tag>``.

    Examples
    --------
    >>> error_html(ValueError("<b>"), style="color:red")
    "<pre class='mocaplab-error' style='color:red'>ValueError: &lt;b&gt;</pre>"
    """
    try:
        name = _text(lambda: type(err).__name__, "exception type")
        message = _text(lambda: str(err), "message")
        if message.startswith("<message could not"):
            message = _text(lambda: object.__repr__(err), "message")
        text = f"{name}: {message}" + (_where(err) if where else "")
        if trace:
            text += "\n" + _text(
                lambda: "".join(traceback.format_exception(type(err), err, err.__traceback__, limit=3)), "traceback"
            )
        if len(text) > MAX_ERROR_TEXT:
            text = f"{text[:MAX_ERROR_TEXT]}... ({len(text) - MAX_ERROR_TEXT} more characters not shown)"
        # lone surrogates (from bytes decoded with surrogateescape) would fail later, when the page is sent
        text = text.encode("utf-8", "backslashreplace").decode("utf-8")
        element = tag if tag in ("pre", "span") else "pre"
        return (
            f"<{element} class='mocaplab-error' style='{html.escape(style, quote=True)}'>"
            f"{html.escape(text)}</{element}>"
        )
    except Exception:  # noqa: BLE001 - the last resort: even building the text failed (out of memory)
        return f"<pre class='mocaplab-error' style='{ERROR_STYLE}'>an error occurred and could not be shown</pre>"


@dataclass(frozen=True)
class Shortcut:
    """A keyboard shortcut of a widget: matplotlib key names, what the help line calls it, the action.

    ``keys`` are matplotlib's names (``"ctrl+z"``, ``" "`` for space,
    ``"left"``); ``shown`` is how the help line writes them.
    """

    keys: tuple[str, ...]
    shown: str
    label: str
    action: Callable[[], object]


def bind_keys(
    canvas: Any, shortcuts: Sequence[Shortcut], *, guard: Callable[[Callable[[], object]], None] | None = None
) -> str:
    """Run each shortcut's action when its key is pressed over ``canvas``; returns the help line.

    With ipympl the keys pressed while the plot has the focus (after a
    click on it) reach the kernel as matplotlib key press events
    (the Agg fallback gets no keys); matplotlib's own keys
    there (``l`` log scale, ``s`` save, ``g`` grid, arrows through the zoom
    history) are switched off, so a key never does something the widget
    does not say.  Tests press keys with
    ``canvas.callbacks.process("key_press_event", KeyEvent(...))``.

    Parameters
    ----------
    canvas : matplotlib FigureCanvas
    shortcuts : sequence of Shortcut
    guard : callable, optional
        Wraps each action (the widget's error display).

    Returns
    -------
    str
        ``"keys (click the plot first): ctrl+z undo · ..."`` (empty without shortcuts).
    """
    run = guard or (lambda action: action())
    manager: Any = getattr(canvas, "manager", None)
    default = getattr(manager, "key_press_handler_id", None)
    if manager is not None and default is not None:
        canvas.mpl_disconnect(default)
        manager.key_press_handler_id = None
    table = {key: s.action for s in shortcuts for key in s.keys}

    def on_key(event: Any) -> None:
        action = table.get(getattr(event, "key", None) or "")
        if action is not None:
            run(action)

    canvas.mpl_connect("key_press_event", on_key)
    return keys_help(shortcuts, "click the plot first")


def keys_help(shortcuts: Sequence[Shortcut], where: str) -> str:
    """The help line of ``shortcuts``: ``"keys (<where>): space play/pause · ..."`` (empty without shortcuts).

    >>> keys_help([Shortcut((" ",), "space", "play/pause", print)], "click the plot first")
    'keys (click the plot first): space play/pause'
    """
    if not shortcuts:
        return ""
    return f"keys ({where}): " + " · ".join(f"{s.shown} {s.label}" for s in shortcuts)


# The browser half of KeyCapture.  Key names are matplotlib's (as ipympl sends them to bind_keys): " ",
# "left", "ctrl+z", "ctrl+Z" with shift; only the keys the widget lists are taken (JupyterLab keeps the others).
_KEYS_ESM = """
const NAMED = {ArrowLeft: "left", ArrowRight: "right", ArrowUp: "up", ArrowDown: "down", Escape: "escape",
               Enter: "enter", Home: "home", End: "end", PageUp: "pageup", PageDown: "pagedown"};
const SLIDER_KEYS = new Set(["left", "right", "up", "down", "home", "end", "pageup", "pagedown"]);
function keyName(e) {
  const base = NAMED[e.key] ?? (e.key.length === 1 ? e.key : null);
  if (base === null) return null;
  return (e.ctrlKey || e.metaKey ? "ctrl+" : "") + (e.altKey ? "alt+" : "") +
    (e.shiftKey && e.key.length !== 1 ? "shift+" : "") + base;
}
export default {
  render({ model, el }) {
    el.classList.add("mocaplab-keys-help");
    el.style.color = "#555";
    el.style.fontSize = "0.9em";
    const show = () => { el.textContent = model.get("help"); };
    show();
    model.on("change:help", show);
    let host = null;
    const onKey = (e) => {
      const name = keyName(e);
      if (name === null || !model.get("key_names").includes(name)) return;
      const target = e.target instanceof Element ? e.target : null;
      if (target && target.closest("input, textarea, select, [contenteditable='true']")) return;  // typing
      if (target && SLIDER_KEYS.has(name) && target.closest(".noUi-target")) return;  // the slider's own keys
      e.preventDefault();  // a focused button is not clicked by space as well, the page does not scroll
      e.stopPropagation();  // nor do JupyterLab's shortcuts act on the key
      model.send({key: name});
    };
    // keys pressed in a 3D view drawn by the browser: its page (an iframe of another origin) posts them
    // here as {mocaplabKey: {key, ctrlKey, metaKey, altKey, shiftKey}}; only this box's own frames count
    const onFrameKey = (e) => {
      const data = e.data && typeof e.data === "object" ? e.data.mocaplabKey : null;
      if (!host || !data || typeof data !== "object" || typeof data.key !== "string") return;
      if (![...host.querySelectorAll("iframe")].some((f) => f.contentWindow === e.source)) return;
      const name = keyName(data);
      if (name !== null && model.get("key_names").includes(name)) model.send({key: name});
    };
    let tries = 0;
    const attach = () => {
      if (!el.isConnected) {
        if (++tries < 600) requestAnimationFrame(attach);
        return;
      }
      host = el.closest("." + model.get("scope")) || el.parentElement;
      if (!host.hasAttribute("tabindex")) host.tabIndex = 0;  // a click on the box (not a control) focuses it
      host.addEventListener("keydown", onKey);
      window.addEventListener("message", onFrameKey);
    };
    attach();
    return () => {
      if (host) host.removeEventListener("keydown", onKey);
      window.removeEventListener("message", onFrameKey);
      model.off("change:help", show);
    };
  },
};
"""


class KeyCapture(anywidget.AnyWidget):  # type: ignore[misc]
    """Keyboard shortcuts over a box of ipywidgets (a widget without a plot: the 3D viewer); shows the help line.

    Placed inside the box whose CSS class is ``scope``, it listens to the
    keys pressed while the focus is in that box (after a click on one of
    its buttons, on the box itself or on this line) or in a browser-drawn
    3D view inside it (its page posts them here), runs the matching
    :class:`Shortcut`'s action in the kernel and leaves every other key to
    JupyterLab.  Keys typed into a text box, and the arrows over a slider
    (which moves itself), are left alone.  Tests press keys with
    :meth:`press`, the browser sends them as ``{"key": name}`` messages.

    Parameters
    ----------
    shortcuts : sequence of Shortcut
    scope : str
        CSS class of the box that listens (an ancestor of this widget).
    where : str
        What the help line says to do first.
    guard : callable, optional
        Wraps each action (the widget's error display).

    Examples
    --------
    >>> pressed = []
    >>> keys = KeyCapture([Shortcut((" ",), "space", "play/pause", lambda: pressed.append("play"))], scope="box")
    >>> keys.help
    'keys (click a button or this line first): space play/pause'
    >>> keys.press(" "), keys.press("q"), pressed
    (True, False, ['play'])
    """

    _esm = _KEYS_ESM
    #: what the help line says to do first, by default
    WHERE = "click a button or this line first"
    #: the keys taken (matplotlib names); every other key is left to JupyterLab
    key_names = traitlets.List(traitlets.Unicode()).tag(sync=True)
    help = traitlets.Unicode("").tag(sync=True)
    scope = traitlets.Unicode("").tag(sync=True)

    def __init__(
        self,
        shortcuts: Sequence[Shortcut],
        *,
        scope: str,
        where: str = WHERE,
        guard: Callable[[Callable[[], object]], None] | None = None,
    ) -> None:
        super().__init__(
            key_names=[key for s in shortcuts for key in s.keys], help=keys_help(shortcuts, where), scope=scope
        )
        self._table = {key: s.action for s in shortcuts for key in s.keys}
        self._run = guard or (lambda action: action())
        self.on_msg(self._on_msg)

    def press(self, key: str) -> bool:
        """Run the action of ``key`` (a matplotlib key name) as if pressed; whether a shortcut took it."""
        action = self._table.get(key)
        if action is None:
            return False
        self._run(action)
        return True

    def _on_msg(self, _widget: Any, content: Any, _buffers: Any) -> None:
        if isinstance(content, dict) and isinstance(content.get("key"), str):
            self.press(content["key"])


def viewer_shortcuts(viewer: Callable[[], Any]) -> list[Shortcut]:
    """Space and the arrows press the play and step buttons of the 3D view ``viewer()`` (None: nothing)."""

    def press(name: str) -> None:
        button = getattr(viewer(), name, None)
        if isinstance(button, W.Button) and not button.disabled:
            button.click()

    return [
        Shortcut((" ",), "space", "play/pause", lambda: press("play")),
        Shortcut(("left",), "\u2190", "frame back", lambda: press("back")),
        Shortcut(("right",), "\u2192", "frame forward", lambda: press("forward")),
    ]


class HistoryButtons:
    """Undo, redo and reset buttons over an editor with ``undo``/``redo``/``reset``/``can_undo``/``can_redo``.

    Parameters
    ----------
    editor : object
        Has ``undo()``, ``redo()``, ``reset()`` and the ``can_undo`` /
        ``can_redo`` properties.
    after : callable
        Called with no argument after each action (the widget redraws).
    guard : callable, optional
        Wraps each action (the widget's error display); default runs it.
    snapshot : callable, optional
        Returns what the widget describes of the editor's state (its
        constraints, its parameters); taken before and after each action and
        kept in :attr:`last`, so the status can say what changed.
    """

    def __init__(
        self,
        editor: Any,
        after: Callable[[], None],
        *,
        guard: Callable[[Callable[[], object]], None] | None = None,
        snapshot: Callable[[], Any] | None = None,
    ) -> None:
        self.editor = editor
        self._after = after
        self._guard = guard or (lambda action: action())
        self._snapshot = snapshot or (lambda: None)
        #: ``(action, state before, state after)`` of the last Undo / Redo / Reset (see :func:`history_status`).
        self.last: tuple[str, Any, Any] | None = None
        layout = W.Layout(width="auto")
        self.undo = W.Button(description="Undo", icon="undo", tooltip="Undo the last edit", layout=layout)
        self.redo = W.Button(description="Redo", icon="repeat", tooltip="Redo the edit undone", layout=layout)
        self.reset = W.Button(
            description="Reset", icon="refresh", tooltip="Back to the input (undoable)", layout=layout
        )
        for button, name in ((self.undo, "undo"), (self.redo, "redo"), (self.reset, "reset")):
            button.add_class(f"mocaplab-{name}")
            button.on_click(lambda _b, name=name: self._run(name))
        self.box = row([self.undo, self.redo, self.reset])
        self.sync()

    def _run(self, name: str) -> None:
        def action() -> None:
            before = self._snapshot()
            try:
                getattr(self.editor, name)()
            finally:
                self.sync()
            self.last = (name, before, self._snapshot())
            self._after()

        self._guard(action)

    def press(self, name: str) -> None:
        """Undo, redo or reset (``name``) as its button does, when the button is enabled (a shortcut)."""
        if not getattr(self, name).disabled:
            self._run(name)

    def shortcuts(self) -> list[Shortcut]:
        """Ctrl+Z undoes, Ctrl+Y (or Ctrl+Shift+Z) redoes."""
        return [
            Shortcut(("ctrl+z",), "ctrl+z", "undo", lambda: self.press("undo")),
            Shortcut(("ctrl+y", "ctrl+Z", "ctrl+shift+z"), "ctrl+y", "redo", lambda: self.press("redo")),
        ]

    def sync(self) -> None:
        """Enable each button exactly when its action is possible."""
        self.undo.disabled = not self.editor.can_undo
        self.redo.disabled = not self.editor.can_redo


_DONE = {"undo": "undid", "redo": "redid", "reset": "reset"}


def history_status(action: str, before: Any, after: Any, describe: Callable[[Any, Any], str]) -> str:
    """What an Undo, Redo or Reset changed, in words: ``"undid: moved pin at frame 40 of character 0"``.

    Parameters
    ----------
    action : {"undo", "redo", "reset"}
    before, after : object
        The editor's state (a widget's snapshot) before and after the action.
    describe : callable
        ``describe(old, new)`` says what an edit from ``old`` to ``new`` did.
        Undo names the edit it took back (from ``after`` to ``before``),
        redo and reset the change they made.

    Examples
    --------
    >>> history_status("undo", 2, 1, lambda old, new: f"{old} -> {new}")
    'undid: 1 -> 2'
    """
    if action not in _DONE:
        raise ValueError(f"Expected `action` to be 'undo', 'redo' or 'reset', got {action!r}")
    what = describe(after, before) if action == "undo" else describe(before, after)
    return f"{_DONE[action]}: {what}"


def export_name(clip: str | None, method: str) -> str:
    """The default export file of a widget: ``<clip>_<method>.bvh`` in letters, digits and ``._-``.

    >>> export_name("16_15", "touched_up"), export_name("my walk (take 2)", "edited"), export_name("", "staggered")
    ('16_15_touched_up.bvh', 'my_walk_take_2_edited.bvh', 'motion_staggered.bvh')
    """
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(clip or "")).strip("._") or "motion"
    return f"{stem}_{method}.bvh"


def free_paths(path: str | os.PathLike[str], n: int) -> list[Path]:
    """:func:`export_paths` of ``path``, or, when one of them exists, of the first free ``stem_2``, ``stem_3`` ...

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp()); (d / "a.bvh").write_text("")
    0
    >>> [f.name for f in free_paths(d / "a.bvh", 1)], [f.name for f in free_paths(d / "a.bvh", 2)]
    (['a_2.bvh'], ['a_1.bvh', 'a_2.bvh'])
    >>> (d / "a_2.bvh").write_text(""); [f.name for f in free_paths(d / "a.bvh", 2)]
    0
    ['a_2_1.bvh', 'a_2_2.bvh']
    """
    files = export_paths(path, n)
    base, k = files[0] if n == 1 else export_paths(path, 1)[0], 1
    while any(f.exists() for f in files):
        k += 1
        files = export_paths(base.with_name(f"{base.stem}_{k}{base.suffix}"), n)
    return files


def export_paths(path: str | os.PathLike[str], n: int) -> list[Path]:
    """File names for ``n`` motions exported to ``path``: the path itself, or ``stem_1.bvh`` ... for several."""
    p = Path(os.fspath(path)).expanduser()
    if p.suffix.lower() != ".bvh":
        p = p.with_name(p.name + ".bvh")
    if n == 1:
        return [p]
    return [p.with_name(f"{p.stem}_{k + 1}{p.suffix}") for k in range(n)]


class ExportControl:
    """A file-name box and an "Export BVH" button writing the editor's current motions.

    Parameters
    ----------
    motions : callable
        Returns the Motion (or sequence of Motions) to write.
    default : str
        Initial file name (see :func:`export_name`).
    guard : callable, optional
        Wraps the write (the widget's error display).

    Notes
    -----
    An existing file is never overwritten without saying so: the export
    writes the first free numbered name (``16_15_edited_2.bvh``,
    :func:`free_paths`) unless ``export(path, overwrite=True)``, and the
    label shows the full path of every file written.
    """

    def __init__(
        self,
        motions: Callable[[], Motion | Sequence[Motion]],
        *,
        default: str = "edited.bvh",
        guard: Callable[[Callable[[], object]], None] | None = None,
    ) -> None:
        self._motions = motions
        self._guard = guard or (lambda action: action())
        self.path = W.Text(
            value=default,
            description="",
            tooltip="file to write (relative to the notebook's folder); an existing file is kept, a numbered name used",
            layout=W.Layout(width="220px"),
        )
        self.path.add_class("mocaplab-export-path")
        self.button = W.Button(description="Export BVH", icon="download", tooltip="Write the edited motion as BVH")
        self.button.add_class("mocaplab-export")
        self.label = W.HTML()
        self.label.add_class("mocaplab-export-status")
        self.written: list[Path] = []
        self.button.on_click(lambda _b: self._guard(self.export))
        self.box = row([self.path, self.button, self.label])

    def export(self, path: str | os.PathLike[str] | None = None, *, overwrite: bool = False) -> list[Path]:
        """Write the current motions (to ``path`` or the box's name); returns the files written (absolute).

        An existing file is kept and the next free numbered name written
        instead (the label says so), unless ``overwrite``.  :attr:`written`
        lists the files written by this call; when a write fails it holds
        those written before the failure, the label says so, and the error
        is raised (the widget shows it).
        """
        self.written = []
        self.label.value = ""
        motions = self._motions()
        ms = [motions] if isinstance(motions, Motion) else list(motions)
        target = Path(os.fspath(self.path.value if path is None else path)).expanduser().absolute()
        asked = export_paths(target, len(ms))
        files = asked if overwrite else free_paths(target, len(ms))
        existing = ", ".join(html.escape(f.name) for f in asked if f.exists()) if files != asked else ""
        for m, f in zip(ms, files, strict=True):
            try:
                save_bvh(m, f)
            except Exception:
                done = ", ".join(html.escape(str(w)) for w in self.written) or "no file"
                self.label.value = (
                    "<span class='mocaplab-error' style='color:#b00020; overflow-wrap:anywhere'>"
                    f"wrote {done} before the failure; {html.escape(str(f))} not written</span>"
                )
                raise
            self.written.append(f)
        names = ", ".join(html.escape(str(f)) for f in files)
        kept = f" ({existing} already there: kept, not overwritten)" if existing else ""
        self.label.value = f"<span class='mocaplab-ok' style='overflow-wrap:anywhere'>wrote {names}{kept}</span>"
        return list(files)
