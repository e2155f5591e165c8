"""HTML report with PNG plots for ``hyst compare`` and ``hyst diagnose`` (matplotlib, Agg backend).

API (stable; ``hyst diagnose`` calls it)::

    write_report(dir, record, model_output, stats, ladder=None, diagnosis=None, *,
                 force=False, title=None) -> pathlib.Path

* ``dir`` — output directory (created). It is refused (:class:`~hyst_model.errors.HystError`) when it already
  holds files that hyst did not write (no ``.hyst-report`` marker), unless ``force``; a previous hyst report in
  it is replaced. The report is written into a hidden directory beside ``dir`` and moved in whole at the
  end, so a crash or a Ctrl-C never leaves half a report.
* ``record`` — :class:`hyst_model.io.Record` (``t`` s, ``u`` V, ``y`` m, ``source``).
* ``model_output`` — model output (m), same length as ``record.y``.
* ``stats`` — :class:`hyst_model.diagnose.stats.CompareStats` of that output.
* ``ladder`` — optional error ladder: a sequence of mappings ``{"model": "mbw+creep", "rmse": 1.2e-8}``
  (validation RMSE in m; optional ``"rmse_train"``), base first.
* ``diagnosis`` — optional mapping as ``hyst diagnose --json`` prints (``baseline``, ``candidates``,
  ``missing``); shown as a table with the evidence sentences.

Returns the directory; its ``index.html`` links ``time.png``, ``loop.png``, ``residual.png``,
``spectrum.png``, ``correlation.png`` and (with a ladder) ``ladder.png``.
"""
from __future__ import annotations

import html
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .report_dir import MARKER, check_report_dir, commit_report
from ..errors import HystError

__all__ = ["write_report", "findings", "MARKER", "check_report_dir"]

def _um(x: float) -> str:
    from ..effects.signals import fmt_len
    return fmt_len(x) if np.isfinite(x) else "n/a"


def findings(st) -> list[str]:
    """Plain-language observations from :class:`~hyst_model.diagnose.stats.CompareStats` (what a lab user should
    look at first); ``hyst compare`` prints them and the report lists them."""
    out: list[str] = []
    o = st.overall
    held, white = st.extra.get("noise_holds"), st.extra.get("noise_white")
    noise = held if held else st.noise_sigma      # noise that is not white, where the holds show it
    q = st.extra.get("noise_step")
    if q:
        out.append(f"The sensor reads in steps of {_um(q)}: its quantisation error "
                   f"with the noise is {_um(st.noise_sigma)} RMS (read by local fits), which no model removes.")
    if held and white:
        out.append(f"The sensor noise read where the input is held still is {_um(held)}, "
                   f"{held / white:.1f}× its white part ({_um(white)}): the noise is not white "
                   "(a sensor slower than the sampling, or the bench vibrating?); no model removes it.")
    if noise > 0 and o.rmse < 1.25 * noise:
        out.append(f"The residual ({_um(o.rmse)} RMS) is at the sensor noise level ({_um(noise)}): "
                   "nothing left to explain.")
    elif noise > 0 and o.rmse < 3.0 * noise:
        out.append(f"The residual ({_um(o.rmse)} RMS) is {o.rmse / noise:.1f}× the output noise ({_um(noise)}): "
                   "small, but the tests below say whether it is structured.")
    if o.rmse > 0 and abs(o.bias) > 0.7 * o.rmse:
        out.append(f"{100 * (o.bias / o.rmse) ** 2:.0f} % of the error power is a constant offset ({_um(o.bias)}): "
                   "check the fitted offset / the sensor zero.")
    segs = [s for s in st.segments if s.fit.n >= 10 and np.isfinite(s.fit.rmse)]
    if len(segs) > 1:
        w = max(segs, key=lambda s: s.fit.rmse)
        if w.fit.rmse > 1.5 * o.rmse:
            out.append(f"The error concentrates in segment '{w.label}' ({w.t0:.3g}–{w.t1:.3g} s): "
                       f"{_um(w.fit.rmse)} RMS vs {_um(o.rmse)} overall.")
        sines = sorted((s for s in segs if s.kind == "sine"), key=lambda s: s.freq)
        if len(sines) >= 2 and sines[-1].fit.rmse > 1.5 * sines[0].fit.rmse:
            out.append(f"The error grows with frequency ({sines[0].freq:.3g} Hz: {_um(sines[0].fit.rmse)}, "
                       f"{sines[-1].freq:.3g} Hz: {_um(sines[-1].fit.rmse)}): rate dependence or dynamics.")
        for h in (s for s in segs if s.kind == "hold"):
            if abs(h.fit.bias) > 0.7 * h.fit.rmse and abs(h.fit.bias) > max(3 * noise, 0.5 * o.rmse):
                where = "above" if h.fit.bias > 0 else "below"
                out.append(f"While the input is held ({h.label}, {h.t0:.3g}–{h.t1:.3g} s) the measured output sits "
                           f"{_um(abs(h.fit.bias))} {where} the model: the rest level differs (offset, creep or "
                           "drift, or an input history before the record that the model does not know).")
    for r in st.extra.get("ringing") or []:
        out.append(f"After the step at t = {r['t']:.4g} s the output rings at ≈{r['freq']:.3g} Hz "
                   f"({_um(r['rms'])} RMS in the first 50 ms): a resonance of the stage the model lacks "
                   "(try the dynamics effect; sample fast enough to see it).")
    lines = st.extra.get("disturbances") or []
    if lines:
        txt = ", ".join(f"{ln['frequency']:.4g} Hz ({_um(ln['amplitude'])} amplitude)" for ln in lines)
        rms = float(np.sqrt(sum(ln["rms"] ** 2 for ln in lines)))
        out.append(f"The output carries {'a line' if len(lines) == 1 else 'lines'} at {txt} that the input does not "
                   f"drive ({_um(rms)} RMS of the residual): mains pickup or an amplifier's ripple — sensor noise no "
                   "model of the stage removes (filter or shield the sensor).")
    # a peak that is one of those lines is said above, not as a resonance
    peaks = [p for p in st.extra.get("peaks") or []
             if not any(abs(p["freq"] - ln["frequency"]) <= 1.0 for ln in lines)]
    if peaks:
        txt = ", ".join(f"{p['freq']:.4g} Hz ({p['ratio']:.0f}×)" for p in peaks)
        out.append(f"The residual spectrum has peaks at {txt} above its local level: resonances or "
                   "vibration the model does not produce (see spectrum.png; the dynamics effect models a "
                   "resonance excited by the input).")
    hm = st.extra.get("harmonics")
    if hm and hm["share"] > 0.3:
        amp = np.asarray(hm["amplitudes"])
        top = np.argsort(amp)[::-1][:3]
        odd = float(np.sum(amp[0::2] ** 2))
        even = float(np.sum(amp[1::2] ** 2))
        kind = ("mostly odd harmonics: a symmetric loop-shape error" if odd > 2 * even else
                "mostly even harmonics: an asymmetric loop (different rising/falling or top/bottom curvature)"
                if even > 2 * odd else "odd and even harmonics: shape and asymmetry errors")
        out.append(f"{100 * hm['share']:.0f} % of the residual during the {hm['freq']:.3g} Hz sine repeats with the "
                   "drive (" + ", ".join(f"{k + 1}× {_um(amp[k])}" for k in top) + f"): {kind}, not noise.")
    br = st.branches
    r, f = br["rising"], br["falling"]
    if r.n > 10 and f.n > 10 and np.isfinite(r.bias) and np.isfinite(f.bias):
        orient = st.extra.get("loop_orientation", 0)
        if abs(r.bias - f.bias) > 0.5 * o.rmse and o.rmse > 0 and orient:
            wide = "wider" if (f.bias - r.bias) * orient > 0 else "narrower"
            out.append(f"Rising and falling branches carry opposite mean errors ({_um(r.bias)} vs {_um(f.bias)}): "
                       f"the measured loop is {wide} than the model's.")
    lv = [f for _, _, f in st.levels if f.n >= 10]
    if len(lv) >= 3 and np.isfinite(lv[0].bias) and np.isfinite(lv[-1].bias):
        if abs(lv[0].bias - lv[-1].bias) > 0.5 * o.rmse and np.sign(lv[0].bias) != np.sign(lv[-1].bias):
            out.append(f"The mean error changes sign from low to high input ({_um(lv[0].bias)} → "
                       f"{_um(lv[-1].bias)}): a gain or end-point error, possibly asymmetry or saturation.")
    bands = [b for b in st.bands if np.isfinite(b.rmse)]
    if bands and o.rmse > 0:
        b = max(bands, key=lambda b: b.rmse)
        share = (b.rmse / o.rmse) ** 2
        if share > 0.5:
            out.append(f"{100 * share:.0f} % of the residual power lies in {b.f_lo:.3g}–{b.f_hi:.3g} Hz.")
    if st.cross.significant:
        lag = st.cross.lag_at_max * (1.0 / st.fs)
        when = "past" if lag >= 0 else "future"
        out.append(f"The residual is correlated with the input (max {st.cross.max_abs:.2f} at {lag * 1e3:.3g} ms, "
                   f"{when} inputs; bound ±{st.cross.bound:.3f}): input-driven behaviour the model lacks.")
    ho = {k: c for k, c in st.higher.items() if c.significant}
    words = {"e2_u": "the error size follows the input level",
             "e_u2": "an even (quadratic) input term is missing — asymmetry or saturation",
             "e_absdu": "the error follows the input speed |du/dt| — rate dependence or dynamics",
             "e2_u2": "the error size follows the input magnitude"}
    for k in ("e_u2", "e_absdu", "e2_u", "e2_u2"):
        if k in ho:
            out.append(f"Higher-order test {k} ({ho[k].max_abs:.2f} > ±{ho[k].bound:.3f}, i.e. about "
                       f"{100 * ho[k].max_abs ** 2:.0f} % of the residual variance): {words[k]}.")
    if not st.auto.significant:
        out.append("The residual is white within the 99 % bounds.")
    return out


def _save(fig, path: Path) -> None:
    """Into the report's staging directory: the whole report is moved into place at the end (write_report)."""
    fig.savefig(path, dpi=110)


def _scale(y: np.ndarray) -> tuple[float, str]:
    a = float(np.nanmax(np.abs(y))) if y.size else 1.0
    if a < 1e-6:
        return 1e9, "nm"
    if a < 1e-3:
        return 1e6, "µm"
    return 1e3, "mm"


def _plots(d: Path, t, u, y, yhat, st, ladder) -> list[tuple[str, str]]:
    import matplotlib
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    e = y - yhat
    k, unit = _scale(np.concatenate([y, yhat]))
    ke, unite = _scale(e)
    figs: list[tuple[str, str]] = []
    # Measured vs model over time, with the input.
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    a1.plot(t, k * y, lw=0.8, label="measured")
    a1.plot(t, k * yhat, lw=0.8, label="model", alpha=0.85)
    a1.set_ylabel(f"output ({unit})")
    a1.legend(loc="upper right")
    a1.set_title("Measured and model output (simulation mode)")
    a2.plot(t, u, lw=0.8, color="0.3")
    a2.set_ylabel("input")
    a2.set_xlabel("time (s)")
    fig.tight_layout()
    _save(fig, d / "time.png")
    plt.close(fig)
    figs.append(("time.png", "Measured and model output over time, with the input"))
    # Loops.
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    ax.plot(u, k * y, lw=0.6, label="measured")
    ax.plot(u, k * yhat, lw=0.6, label="model", alpha=0.85)
    ax.set_xlabel("input")
    ax.set_ylabel(f"output ({unit})")
    ax.set_title("Loops: output vs input")
    ax.legend()
    fig.tight_layout()
    _save(fig, d / "loop.png")
    plt.close(fig)
    figs.append(("loop.png", "Hysteresis loops, measured and model"))
    # Residual with u and du/dt.
    dt = 1.0 / st.fs
    du = np.gradient(u, dt) if u.size > 1 else np.zeros_like(u)
    fig, (b1, b2, b3) = plt.subplots(3, 1, figsize=(10, 6.5), sharex=True)
    b1.plot(t, ke * e, lw=0.7, color="C3")
    b1.axhline(0, color="0.5", lw=0.5)
    b1.set_ylabel(f"residual ({unite})")
    b1.set_title("Residual (measured − model) with the input and its rate")
    for s in st.segments:  # shade segment boundaries so "where" is visible
        b1.axvline(s.t0, color="0.8", lw=0.5)
    b2.plot(t, u, lw=0.7, color="0.3")
    b2.set_ylabel("u")
    b3.plot(t, du, lw=0.7, color="0.3")
    b3.set_ylabel("du/dt (1/s)")
    b3.set_xlabel("time (s)")
    fig.tight_layout()
    _save(fig, d / "residual.png")
    plt.close(fig)
    figs.append(("residual.png", "Residual vs time, input and input rate"))
    # Spectra: Welch amplitude spectral density (averaged, readable on long records).
    from scipy.signal import welch
    n = y.size
    nper = int(min(n, max(256, n // 8)))
    f, Py = welch(y - y.mean(), st.fs, nperseg=nper)
    _, Pe = welch(e - e.mean(), st.fs, nperseg=nper)
    fig, ax = plt.subplots(figsize=(10, 4.5))
    ax.loglog(f[1:], k * np.sqrt(Py[1:]) + 1e-30, lw=0.8, label="measured")
    ax.loglog(f[1:], k * np.sqrt(Pe[1:]) + 1e-30, lw=0.8, label="residual", color="C3")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude density ({unit}/√Hz)")
    ax.set_title("Amplitude spectral density (Welch)")
    ax.legend()
    fig.tight_layout()
    _save(fig, d / "spectrum.png")
    plt.close(fig)
    figs.append(("spectrum.png", "Amplitude spectral density of the measured output and the residual"))
    # Correlations with bounds.
    cors = [st.auto, st.cross, *st.higher.values()]
    fig, axs = plt.subplots(2, 3, figsize=(12, 6))
    for ax, c in zip(axs.ravel(), cors):
        lag_ms = c.lags * c.dt * 1e3
        ax.axhspan(-c.bound, c.bound, color="C0", alpha=0.15, lw=0)
        ax.vlines(lag_ms, 0, c.values, color="C3" if c.significant else "C0", lw=1.2)
        ax.plot(lag_ms, c.values, ".", color="C3" if c.significant else "C0", ms=3)
        ax.axhline(0, color="0.4", lw=0.5)
        ax.set_title({"auto": "residual autocorrelation", "cross": "residual–input cross-corr."}.get(c.name, c.name),
                     fontsize=9)
        ax.set_xlabel("lag (ms)", fontsize=8)
    for ax in axs.ravel()[len(cors):]:
        ax.axis("off")
    fig.suptitle("Residual tests; shaded: 99 % confidence region (red: significant)")
    fig.tight_layout()
    _save(fig, d / "correlation.png")
    plt.close(fig)
    figs.append(("correlation.png", "Whiteness, cross-correlation and higher-order tests with 99 % bounds"))
    if ladder:
        labels = [str(r.get("model", "?")) for r in ladder]
        val = np.array([float(r.get("rmse", np.nan)) for r in ladder])
        kk, uu = _scale(val[np.isfinite(val)] if np.isfinite(val).any() else np.array([1e-6]))
        fig, ax = plt.subplots(figsize=(max(6, 1.4 * len(labels)), 4))
        ax.bar(range(len(labels)), kk * val, color="C0", label="validation")
        tr = [r.get("rmse_train") for r in ladder]
        if any(x is not None for x in tr):
            ax.plot(range(len(labels)), [kk * float(x) if x is not None else np.nan for x in tr], "o",
                    color="C1", label="training")
            ax.legend()
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=20, ha="right")
        ax.set_ylabel(f"RMSE ({uu})")
        ax.set_title("Error ladder: validation RMSE as effects are added")
        for i, v in enumerate(val):
            if np.isfinite(v):
                ax.annotate(f"{kk * v:.3g}", (i, kk * v), ha="center", va="bottom", fontsize=8)
        fig.tight_layout()
        _save(fig, d / "ladder.png")
        plt.close(fig)
        figs.append(("ladder.png", "Error ladder"))
    return figs


def _fmt(x: Any) -> str:
    if isinstance(x, (float, np.floating)):
        return "n/a" if not np.isfinite(x) else f"{x:.4g}"
    return html.escape(str(x))


def _table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    b = "".join("<tr>" + "".join(f"<td>{_fmt(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{b}</table>"


def _nm(x: float) -> float:
    return x * 1e9


def write_report(dir: str | os.PathLike, record, model_output: np.ndarray, stats,
                 ladder: Sequence[Mapping[str, Any]] | None = None, diagnosis: Mapping[str, Any] | None = None,
                 *, force: bool = False, title: str | None = None, kind: str = "report") -> Path:
    """Write ``index.html`` and the PNG plots into ``dir`` (see the module docstring); return ``dir``. ``kind``
    names the command (``compare``, ``diagnose``): another command's report there needs ``force``."""
    t = np.asarray(record.t, float)
    u = np.asarray(record.u, float)
    y = np.asarray(record.y, float)
    yhat = np.asarray(model_output, float)
    if not (t.size == u.size == y.size == yhat.size) or t.size < 8:
        raise HystError("report: record and model output must have the same length (at least 8 samples)")
    target = check_report_dir(dir, force, kind)
    # Everything is written into a hidden directory beside the target and moved in at the end: a Ctrl-C or a
    # failure while plotting (seconds) left a report without index.html, or beside a params file already written.
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        d = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".staging", dir=target.parent))
    except OSError as err:
        raise HystError(f"cannot create report directory {target}: {err}") from err
    try:
        _write_into(d, t, u, y, yhat, record, stats, ladder, diagnosis, title)
        (d / MARKER).write_text(f"written by hyst {kind}; files listed in index.html are replaced on the next "
                                f"{kind} report\n")
        commit_report(d, target)
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return target


def _lines_taken(diagnosis: Mapping[str, Any]) -> str:
    """The lines a diagnosis took out of the record, in words ("" for none)."""
    from .lines import Line, said
    return said([Line(float(ln["frequency"]), float(ln["amplitude"]), 0.0)
                 for ln in diagnosis.get("disturbances", []) or [] if ln.get("removed")])


def _write_into(d: Path, t, u, y, yhat, record, stats, ladder, diagnosis, title) -> None:
    """The plots and index.html of :func:`write_report`, into directory ``d``."""
    figs = _plots(d, t, u, y, yhat, stats, ladder)
    st = stats
    o = st.overall
    parts = [f"<h1>{html.escape(title or 'hyst report')}</h1>",
             f"<p>data: {html.escape(str(getattr(record, 'source', '')))} — {o.n} samples at {st.fs:.6g} Hz; "
             f"output noise ≈ {_nm(st.noise_sigma):.3g} nm"
             + (f" (read in steps of {_nm(st.extra['noise_step']):.3g} nm: quantisation error and noise)"
                if st.extra.get("noise_step") else "") + "</p>"]
    if diagnosis:
        bl = diagnosis.get("baseline", {}) or {}
        parts.append(f"<h2>Diagnosis</h2><p>baseline {html.escape(str(bl.get('model', '?')))}: RMSE "
                     f"{_nm(float(bl.get('rmse', np.nan))):.4g} nm. Missing effect: "
                     f"<b>{html.escape(str(diagnosis.get('missing', '?')))}</b></p>")
        rows = [(c.get("effect"), _nm(float(c.get("rmse", np.nan))), c.get("improvement"), c.get("evidence", ""))
                for c in diagnosis.get("candidates", [])]
        parts.append(_table(["effect", "validation RMSE (nm)", "improvement", "evidence"], rows))
        taken = _lines_taken(diagnosis)
        if taken:
            parts.append(f"<p>Taken out of the record before fitting: {html.escape(taken)}, which the input does "
                         "not drive (mains pickup or an amplifier's ripple?). Every RMSE of the diagnosis and the "
                         "ladder is of the record without them; the fit figures and plots below are of the record as "
                         "measured (the lines show there).</p>")
    if ladder:
        rungs = [(r.get("model"), _nm(float(r.get("rmse", np.nan))),
                  _nm(float(r["rmse_train"])) if r.get("rmse_train") is not None else "") for r in ladder]
        parts.append("<h2>Error ladder</h2>" + _table(["model", "validation RMSE (nm)", "training RMSE (nm)"], rungs))
    parts.append("<h2>Findings</h2><ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in findings(st)) + "</ul>")
    parts.append("<h2>Fit figures</h2>" + _table(
        ["", "n", "RMSE (nm)", "NRMSE (%)", "fit (%)", "bias (nm)", "max (nm)"],
        [("overall", o.n, _nm(o.rmse), 100 * o.nrmse, o.fit_percent, _nm(o.bias), _nm(o.max_abs))]))
    parts.append("<h3>By time segment</h3>" + _table(
        ["segment", "t0 (s)", "t1 (s)", "RMSE (nm)", "fit (%)", "bias (nm)"],
        [(s.label, s.t0, s.t1, _nm(s.fit.rmse), s.fit.fit_percent, _nm(s.fit.bias)) for s in st.segments]))
    parts.append("<h3>By branch</h3>" + _table(
        ["branch", "n", "RMSE (nm)", "bias (nm)"],
        [(k, f.n, _nm(f.rmse), _nm(f.bias)) for k, f in st.branches.items()]))
    parts.append("<h3>By input level</h3>" + _table(
        ["from", "to", "n", "RMSE (nm)", "bias (nm)"],
        [(lo, hi, f.n, _nm(f.rmse), _nm(f.bias)) for lo, hi, f in st.levels]))
    parts.append("<h3>By frequency band</h3>" + _table(
        ["from (Hz)", "to (Hz)", "residual RMS (nm)", "measured RMS (nm)", "fit (%)"],
        [(b.f_lo, b.f_hi, _nm(b.rmse), _nm(b.y_rms), b.fit_percent) for b in st.bands]))
    parts.append("<h3>Residual tests (99 % bounds)</h3>" + _table(
        ["test", "max |r|", "at lag (ms)", "bound", "lags outside (%)", "verdict"],
        [(c.name, c.max_abs, c.lag_at_max * c.dt * 1e3, c.bound, 100 * c.frac_outside,
          "significant" if c.significant else "ok") for c in [st.auto, st.cross, *st.higher.values()]]))
    for name, caption in figs:
        parts.append(f"<figure><img src='{name}' alt='{html.escape(caption)}'>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    css = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto}table{border-collapse:collapse;"
           "margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}img{max-width:100%}")
    doc = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title or 'hyst report')}"
           f"</title><style>{css}</style></head><body>{''.join(parts)}</body></html>\n")
    (d / "index.html").write_text(doc, encoding="utf-8")
