"""The small C runtime added to the FMU that CasADi exports, for models with asserts, initial
equations or events (:mod:`.fmi_export` says when and what the FMI functions then do).

The assert conditions are outputs of the model function itself (local variables ``_tbx_a<k>``, 1
where the assert holds: :func:`.fmi_export.build_dae`), so the evaluation the solver asks for
anyway gives them and the runtime only reads them. The initialisation solve and one step of the
event iteration are CasADi functions generated into ``tbx_runtime.c`` (its own translation unit,
listed in ``buildDescription.xml``); the wrapper's FMI functions are patched to call them: C
templates for the asserts, the initialisation (a residual above :data:`INIT_TOLERANCE` fails it), the event
iteration, ``fmi3UpdateDiscreteStates`` and ``fmi3GetEventIndicators``.
"""
from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import casadi as ca

from ..errors import CompileError
from .events import MAX_EVENT_ITERATIONS
from .flat_model import Assertion, ExplicitModel


#: the largest residual of an initial equation accepted after the Newton solve
INIT_TOLERANCE = 1e-6

_TIME_VR = -1  # marks the time in the runtime's tables of value references


CHATTER_EVENTS = 1000
"""Events in a row, each within :data:`CHATTER_SPACING` of the last, after which the FMU stops with
an error saying the model chatters (a relation that its own event flips back, over and over: the
integrator would otherwise creep on by 1e-13 s per event and never finish)."""

CHATTER_SPACING = 1e-9
"""Seconds (relative to max(1, |t|)) within which two events count as one burst (see above)."""


EVENT_PASSES = 40
"""Passes of one event-iteration step (pre values held) after which the step's passes count as a
cycle and the relations that changed in the second half are searched (``tbx_search_relations``)."""

SEARCH_RELATIONS = 12
"""At most this many cycling relations are searched (2^12 combinations); more fail the step."""


def value_references(xml: str) -> dict[str, int]:
    root = ET.fromstring(xml)
    variables = root.find("ModelVariables")
    refs: dict[str, int] = {}
    for var in (variables if variables is not None else []):
        refs[var.get("name", "")] = int(var.get("valueReference", "0"))
    return refs


def fmu_asserts(em: ExplicitModel) -> list[Assertion]:
    """The asserts the FMU checks: one per message and level, in the order of their first
    appearance, holding where all of that message's hold (each traced call of an IF97 function
    brings its own copies: ``MomentumBalanceFittings`` has 1 524 asserts, one output each of the
    model function, for far fewer messages). A failure names the same message as before; a
    warning logs once per violation of any of them."""
    groups: dict[tuple[str, str], list[Assertion]] = {}
    for a in em.asserts:
        groups.setdefault((a.message, a.level), []).append(a)
    out = []
    for group in groups.values():
        first = group[0]
        cond = first.condition if len(group) == 1 else ca.mmin(ca.vertcat(*[a.condition for a in group]))
        out.append(Assertion(condition=cond, message=first.message, level=first.level, origin=first.origin))
    return out


def _c_string(text: str) -> str:
    """A C string literal of *text* (UTF-8, every byte outside printable ASCII as an octal escape)."""
    out = []
    for byte in text.encode("utf-8"):
        ch = chr(byte)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= byte < 127 and ch != "?":
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def _c_array(ctype: str, name: str, values: list[str]) -> str:
    body = ", ".join(values) if values else "0"
    return f"static const {ctype} {name}[{max(len(values), 1)}] = {{{body}}};\n"


def _vrs(syms: list[ca.MX], refs: dict[str, int], model: str, what: str) -> list[str]:
    out = []
    for sym in syms:
        name = sym.name()
        if name not in refs and name.startswith("pre(") and name.endswith(")") and name[4:-1] in refs:
            name = name[4:-1]  # pre(v) that the FMU does not hold: v's value when it is called
        if name == "time":
            out.append(str(_TIME_VR))
        elif name in refs:
            out.append(str(refs[name]))
        else:
            raise CompileError(f"{what} of {model} uses {name!r}, which the exported FMU does not have")
    return out


def _work_defines(prefix: str, fn: ca.Function) -> str:
    return (f"#define {prefix}_SZ_ARG {fn.sz_arg()}\n#define {prefix}_SZ_RES {fn.sz_res()}\n"
            f"#define {prefix}_SZ_IW {fn.sz_iw()}\n#define {prefix}_SZ_W {fn.sz_w()}\n")


_CALL = """
static int tbx_call_%(fn)s(const casadi_real** arg, casadi_real** res) {
  casadi_int* iw = (casadi_int*)malloc(sizeof(casadi_int) * (%(P)s_SZ_IW + 1));
  casadi_real* w = (casadi_real*)malloc(sizeof(casadi_real) * (%(P)s_SZ_W + 1));
  int mem, flag = 1;
  if (iw && w) {
    mem = %(fn)s_checkout();
    flag = %(fn)s(arg, res, iw, w, mem);
    %(fn)s_release(mem);
  }
  free(iw);
  free(w);
  return flag;
}
"""

_COMMON = """
/* trackingbox runtime: asserts and initial equations (generated by trackingbox.compiler.fmi_export) */
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
static double tbx_value(casadi_fmi_memory* m, long vr) {
  return vr < 0 ? m->t : m->v[var_offset[vr]];
}
static void tbx_log(casadi_fmi_memory* m, fmi3Status status, const char* category, const char* text) {
  if (m->tbx_logger) m->tbx_logger(m->tbx_env, status, category, text);
}
"""

_ASSERTS = """
static int tbx_eval_asserts(casadi_fmi_memory* m, casadi_real* c) {
  /* the conditions are outputs of the model function (_tbx_a<k>): one evaluation gives them */
  size_t k;
  if (!m->up_to_date) {
    if (evaluate(m)) return 1;
    m->up_to_date = 1;
  }
  for (k = 0; k < TBX_N_ASSERT; ++k) c[k] = m->v[var_offset[tbx_a_vr[k]]];
  return 0;
}
/* At the solver's trial points (derivative calls) a failing error-level assert is only noted
   (category assert-trial, status OK): the step may be rejected. If the solver then fails, the
   importer can report the assert; a completed step clears the note. */
static void tbx_note_asserts(casadi_fmi_memory* m) {
  casadi_real c[TBX_N_ASSERT + 1];
  char text[1400];
  int k;
  if (m->tbx_pending >= 0 || tbx_eval_asserts(m, c)) return;
  for (k = 0; k < TBX_N_ASSERT; ++k) {
    if (tbx_a_error[k] && !(c[k] > 0.5)) {
      m->tbx_pending = k;
      snprintf(text, sizeof text, "assert failed at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3OK, "assert-trial", text);
      return;
    }
  }
}
static fmi3Status tbx_check_asserts(casadi_fmi_memory* m) {
  casadi_real c[TBX_N_ASSERT + 1];
  char text[1400];
  int k;
  if (tbx_eval_asserts(m, c)) return fmi3Error;
  m->tbx_pending = -1;
  for (k = 0; k < TBX_N_ASSERT; ++k) {
    if (c[k] > 0.5) {
      m->tbx_warned[k] = 0;
      continue;
    }
    if (tbx_a_error[k]) {
      snprintf(text, sizeof text, "assert failed at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3Error, "assert", text);
      return fmi3Error;
    }
    if (!m->tbx_warned[k]) {
      snprintf(text, sizeof text, "assert warning at t = %.17g s: %s", m->t, tbx_a_message[k]);
      tbx_log(m, fmi3Warning, "assert", text);
      m->tbx_warned[k] = 1;
    }
  }
  return fmi3OK;
}
"""

_INIT = """
static fmi3Status tbx_initialize(casadi_fmi_memory* m) {
  casadi_real z0[TBX_I_NZ + 1], wk[TBX_I_NK + 1], z[TBX_I_NZ + 1], r[TBX_I_NZ + 1];
  const casadi_real* arg[TBX_I_SZ_ARG + 1];
  casadi_real* res[TBX_I_SZ_RES + 1];
  char text[1400];
  size_t i, worst = 0;
  for (i = 0; i < TBX_I_NZ; ++i) z0[i] = m->v[var_offset[tbx_i_unknown_vr[i]]];
  for (i = 0; i < TBX_I_NK; ++i) wk[i] = tbx_value(m, tbx_i_known_vr[i]);
  arg[0] = z0;
  arg[1] = wk;
  res[0] = z;
  res[1] = r;
  if (tbx_call_tbx_init(arg, res)) {
    tbx_log(m, fmi3Error, "init", "initialisation failed: the Newton solve of the initial equations failed");
    return fmi3Error;
  }
  /* an unknown the solve left non-finite is named first (its residual may read 0), then the
     equation with the largest residual (a NaN one before any finite one) */
  for (i = 0; i < TBX_I_NZ; ++i) {
    if (!isfinite(z[i])) {
      snprintf(text, sizeof text, "initialisation failed at t = %.17g s: the initial equations have no "
               "solution near the start values (their solve gives %s = %g)", m->t, tbx_i_name[i], z[i]);
      tbx_log(m, fmi3Error, "init", text);
      return fmi3Error;
    }
  }
  for (i = 0; i < TBX_I_NZ; ++i) {
    if (isnan(r[worst])) break;
    if (isnan(r[i]) || fabs(r[i]) > fabs(r[worst])) worst = i;
  }
  if (TBX_I_NZ > 0 && !(fabs(r[worst]) <= TBX_I_TOL)) {
    snprintf(text, sizeof text, "initialisation failed at t = %.17g s: the initial equations have no "
             "solution near the start values (residual %g of the %s)", m->t, r[worst], tbx_i_origin[worst]);
    tbx_log(m, fmi3Error, "init", text);
    return fmi3Error;
  }
  for (i = 0; i < TBX_I_NZ; ++i) m->v[var_offset[tbx_i_unknown_vr[i]]] = z[i];
  m->up_to_date = 0;
  return fmi3OK;
}
"""


_EVENTS = """
static int tbx_event_step(casadi_fmi_memory* m, int quiet, int given, casadi_real* out) {
  casadi_real win[TBX_E_NW + 1];
  casadi_real q = quiet ? 1 : 0;
  const casadi_real* arg[TBX_E_SZ_ARG + 1];
  casadi_real* res[TBX_E_SZ_RES + 1];
  size_t i;
  if (!m->up_to_date) {
    if (evaluate(m)) return 1;
    m->up_to_date = 1;
  }
  for (i = 0; i < TBX_E_NW; ++i) win[i] = tbx_value(m, tbx_e_vr[i]);
  arg[0] = win;
  arg[1] = &q;
  res[0] = out;
  return given ? tbx_call_tbx_event_given(arg, res) : tbx_call_tbx_event(arg, res);
}
/* Write the updates of *out*; 1 if one changed. */
static int tbx_write_updates(casadi_fmi_memory* m, const casadi_real* out) {
  int changed = 0;
  size_t k;
  for (k = 0; k < TBX_E_NU; ++k) {
    casadi_real* v = &m->v[var_offset[tbx_e_upd_vr[k]]];
    if (*v != out[k]) {
      *v = out[k];
      changed = 1;
    }
  }
  m->up_to_date = 0;
  return changed;
}
/* Whether the relations of *out* (a pass with the relations recomputed) that differ from those the
   FMU holds (at least one) are all at a tie: each such relation's indicator, shifted by the
   hysteresis towards the held value, still gives the held value (its operands are equal within the
   hysteresis), so the held value is as consistent as the other. Rounding conditions never tie. The
   discrete variables of *out* follow from the recomputed relations: the caller checks that those
   the held relations select reproduce themselves. */
static int tbx_only_ties(casadi_fmi_memory* m, const casadi_real* out) {
  size_t k;
  int differ = 0;
  for (k = 0; k < TBX_E_NU; ++k) {
    casadi_real held = m->v[var_offset[tbx_e_upd_vr[k]]], z;
    if (held == out[k]) continue;
    if (k >= TBX_E_NC) continue;  /* a discrete variable: follows the relations (checked after) */
    if (tbx_c_z[k] < 0) return 0;
    z = m->v[var_offset[tbx_z_vr[tbx_c_z[k]]]];
    if (!(held != 0 ? z > 0 : z < 0)) return 0;
    differ = 1;
  }
  return differ;
}
/* The passes of a step cycle (relations that the discrete values they select flip back): search the
   relations that changed in the cycle, every combination of their values (at most 2^TBX_E_SEARCH),
   for one that the discrete variables it selects and the continuous values that follow reproduce
   (the mixed system's solution). Fewest changes from the current values first. 0: found (*out*
   holds its pass), 1: none, -1: the model could not be evaluated. */
static int tbx_search_relations(casadi_fmi_memory* m, int quiet, const int* flipped, casadi_real* out) {
  size_t idx[TBX_E_NC + 1], n = 0, k, b;
  casadi_real base[TBX_E_NC + 1], keep[TBX_E_NU + 1];
  unsigned long mask, count;
  int bits;
  for (k = 0; k < TBX_E_NC; ++k) {
    if (flipped[k]) idx[n++] = k;
  }
  if (n == 0 || n > TBX_E_SEARCH) return 1;
  for (k = 0; k < TBX_E_NU; ++k) keep[k] = m->v[var_offset[tbx_e_upd_vr[k]]];
  for (k = 0; k < n; ++k) base[k] = keep[idx[k]];
  count = 1UL << n;
  for (bits = 0; bits <= (int)n; ++bits) {
    for (mask = 0; mask < count; ++mask) {
      unsigned long x = mask;
      int ones = 0;
      while (x) { ones += (int)(x & 1UL); x >>= 1; }
      if (ones != bits) continue;
      for (k = 0; k < TBX_E_NU; ++k) m->v[var_offset[tbx_e_upd_vr[k]]] = keep[k];
      for (b = 0; b < n; ++b) {
        casadi_real flip = (mask >> b) & 1UL ? 1 : 0;
        m->v[var_offset[tbx_e_upd_vr[idx[b]]]] = flip ? (base[b] != 0 ? 0 : 1) : base[b];
      }
      m->up_to_date = 0;
      if (tbx_event_step(m, quiet, 1, out)) return -1;
      tbx_write_updates(m, out);
      if (tbx_event_step(m, quiet, 0, out)) return -1;
      if (tbx_only_ties(m, out)) {  /* consistent up to ties: the held relations stand */
        if (tbx_event_step(m, quiet, 1, out)) return -1;
        if (!tbx_write_updates(m, out)) return 0;
        continue;
      }
      if (!tbx_write_updates(m, out)) return 0;
    }
  }
  for (k = 0; k < TBX_E_NU; ++k) m->v[var_offset[tbx_e_upd_vr[k]]] = keep[k];
  m->up_to_date = 0;
  return 1;
}
/* The event iteration (trackingbox.compiler.events, MLS 8.6). Each step: pre(v) := v, then passes
   with these pre values held (relations from the continuous-time values of the current iterate,
   the discrete variables, the continuous part again) until no discrete value changes: the mixed
   system of the step solved by fixed-point iteration; then the step's re-initialisations. Steps
   are repeated until one changes nothing (pre(v) == v). Then the next sample() instant, if any. */
static fmi3Status tbx_event_iteration(casadi_fmi_memory* m, int quiet, int* states_changed) {
  casadi_real out[TBX_E_NOUT + 1];
  char text[400];
  casadi_real first[TBX_E_NOUT + 1];
  int it, pass, found, changed = 0, fallbacks = 0, unsettled = 0;
  int flipped[TBX_E_NC + 1];
  size_t k, j;
  for (it = 0; it < TBX_E_MAXIT; ++it) {
    for (k = 0; k < TBX_E_NP; ++k) m->v[var_offset[tbx_e_pre_vr[k]]] = m->v[var_offset[tbx_e_pre_of_vr[k]]];
    m->up_to_date = 0;
    for (k = 0; k < TBX_E_NC; ++k) flipped[k] = 0;
    unsettled = 0;
    for (pass = 0;; ++pass) {
      if (pass >= TBX_E_PASSES) {
        found = tbx_search_relations(m, quiet, flipped, out);
        if (found == 0) break;
        if (found < 0) {
          snprintf(text, sizeof text, "event iteration at t = %.17g s: the model could not be evaluated", m->t);
          tbx_log(m, fmi3Error, "event", text);
          return fmi3Error;
        }
        /* no consistent combination with these pre values: the step is its first pass (the
           values it gave become the pre values of the next step), as in an iteration whose every
           pass is a step; a model that needs that forever fails after TBX_E_MAXIT steps */
        for (k = 0; k < TBX_E_NOUT; ++k) out[k] = first[k];
        tbx_write_updates(m, out);
        ++fallbacks;
        unsettled = 1;
        break;
      }
      if (tbx_event_step(m, quiet, 0, out)) {
        snprintf(text, sizeof text, "event iteration at t = %.17g s: the model could not be evaluated", m->t);
        tbx_log(m, fmi3Error, "event", text);
        return fmi3Error;
      }
      if (pass == 0) {
        for (k = 0; k < TBX_E_NOUT; ++k) first[k] = out[k];
      }
      if (pass >= TBX_E_PASSES / 2) {  /* the relations that still change: the search's candidates */
        for (k = 0; k < TBX_E_NC; ++k) {
          if (m->v[var_offset[tbx_e_upd_vr[k]]] != out[k]) flipped[k] = 1;
        }
      }
      if (!tbx_write_updates(m, out)) break;
    }
    /* the last pass changed nothing (or the step fell back to its first pass, which calls for
       another step): its re-initialisations are those of the step */
    changed = unsettled;
    for (k = 0; k < TBX_E_NR; ++k) {
      casadi_real* v = &m->v[var_offset[tbx_e_reinit_vr[k]]];
      if (*v != out[TBX_E_NU + k]) {
        *v = out[TBX_E_NU + k];
        changed = 1;
        *states_changed = 1;
      }
    }
    for (k = 0; k < TBX_E_NP; ++k) {
      if (m->v[var_offset[tbx_e_pre_vr[k]]] != m->v[var_offset[tbx_e_pre_of_vr[k]]]) changed = 1;
    }
    m->up_to_date = 0;
    if (!changed) {
      m->tbx_next_defined = 0;
      for (j = 0; j < TBX_E_NS; ++j) {
        casadi_real start = out[TBX_E_NU + TBX_E_NR + j];
        casadi_real interval = out[TBX_E_NU + TBX_E_NR + TBX_E_NS + j];
        casadi_real eps = 1e-9 * fmax(1.0, fabs(m->t)), n, tn;
        if (!(interval > 0)) continue;
        n = ceil((m->t - start) / interval);
        if (n < 0) n = 0;
        tn = start + n * interval;
        if (tn <= m->t + eps) tn = start + (n + 1) * interval;
        if (!m->tbx_next_defined || tn < m->tbx_next) {
          m->tbx_next = tn;
          m->tbx_next_defined = 1;
        }
      }
      return fmi3OK;
    }
  }
  snprintf(text, sizeof text, "event iteration at t = %.17g s did not converge after %d steps (%d of them with "
           "discrete variables that do not settle: a mixed system of discrete and continuous equations without "
           "a consistent solution)", m->t, TBX_E_MAXIT, fallbacks);
  tbx_log(m, fmi3Error, "event", text);
  return fmi3Error;
}
static int tbx_samples_on(casadi_fmi_memory* m) {
  size_t j;
  for (j = 0; j < TBX_E_NS; ++j) {
    if (m->v[var_offset[tbx_e_sample_vr[j]]] != 0) return 1;
  }
  return 0;
}
/* Initialisation with events: initial() is true; the initial equations and the event iteration are
   repeated until the held values no longer change (the continuous part depends on them). */
static fmi3Status tbx_initialize_events(casadi_fmi_memory* m) {
  casadi_real held[TBX_E_NU + 1];
  int round, changed = 0;
  size_t k;
  m->v[var_offset[TBX_E_INIT_VR]] = 1;
  for (k = 0; k < TBX_E_NP; ++k) m->v[var_offset[tbx_e_pre_vr[k]]] = m->v[var_offset[tbx_e_pre_of_vr[k]]];
  m->up_to_date = 0;
  for (round = 0; round < 20; ++round) {
#ifdef TBX_I_NZ
    if (tbx_initialize(m) != fmi3OK) return fmi3Error;
#endif
    for (k = 0; k < TBX_E_NU; ++k) held[k] = m->v[var_offset[tbx_e_upd_vr[k]]];
    if (tbx_event_iteration(m, 0, &changed) != fmi3OK) return fmi3Error;
#ifndef TBX_I_NZ
    break;
#endif
    changed = 0;
    for (k = 0; k < TBX_E_NU; ++k) {
      if (held[k] != m->v[var_offset[tbx_e_upd_vr[k]]]) changed = 1;
    }
    if (!changed) break;
  }
#ifdef TBX_N_ASSERT
  /* the asserts hold at initialisation too, where initial() is true (e.g. `if initial() then assert(...)`) */
  if (tbx_check_asserts(m) != fmi3OK) return fmi3Error;
#endif
  m->v[var_offset[TBX_E_INIT_VR]] = 0;
  m->up_to_date = 0;
  return fmi3OK;
}
"""

_UPDATE_DISCRETE = """FMI3_Export fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance,
    fmi3Boolean* discreteStatesNeedUpdate,
    fmi3Boolean* terminateSimulation,
    fmi3Boolean* nominalsOfContinuousStatesChanged,
    fmi3Boolean* valuesOfContinuousStatesChanged,
    fmi3Boolean* nextEventTimeDefined,
    fmi3Float64* nextEventTime) {
  // trackingbox runtime: the event iteration (trackingbox.compiler.events)
  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;
  int states_changed = 0;
  fmi3Status status;
  // chattering: events in a row, each within TBX_CHATTER_DT (relative) of the last one
  if (m->tbx_burst >= 0 && fabs(m->t - m->tbx_last_event) <= TBX_CHATTER_DT * fmax(1.0, fabs(m->t))) {
    if (++m->tbx_burst >= TBX_CHATTER_N) {
      char text[300];
      snprintf(text, sizeof text, "the model chatters at t = %.17g s: %d events in a row, each within "
               "%g s of the last (a switch that its own event undoes)", m->t, TBX_CHATTER_N,
               TBX_CHATTER_DT * fmax(1.0, fabs(m->t)));
      tbx_log(m, fmi3Error, "event", text);
      return fmi3Error;
    }
  } else {
    m->tbx_burst = 0;
  }
  m->tbx_last_event = m->t;
  status = tbx_event_iteration(m, 0, &states_changed);
  *discreteStatesNeedUpdate = fmi3False;
  *terminateSimulation = fmi3False;
  *nominalsOfContinuousStatesChanged = fmi3False;
  *valuesOfContinuousStatesChanged = (states_changed || m->continuous_states_changed) ? fmi3True : fmi3False;
  *nextEventTimeDefined = m->tbx_next_defined ? fmi3True : fmi3False;
  if (m->tbx_next_defined) *nextEventTime = m->tbx_next;
  m->continuous_states_changed = 0;
  return status;
}
"""

_EVENT_INDICATORS = """FMI3_Export fmi3Status fmi3GetEventIndicators(fmi3Instance instance,
    fmi3Float64 eventIndicators[],
    size_t nEventIndicators) {
  // trackingbox runtime: the indicators of the frozen relations (trackingbox.compiler.events)
  (void)nEventIndicators;
  if (TBX_NZ == 0) return fmi3OK;
  return fmi3GetFloat64(instance, tbx_z_vr, TBX_NZ, eventIndicators, TBX_NZ);
}
"""


def _runtime_functions(em: ExplicitModel) -> tuple[list[ca.Function], list[ca.MX]]:
    """The CasADi function ``tbx_init(z0, wk) -> (z, r)`` (where the model has initial equations) and
    its known symbols (the asserts' conditions are outputs of the model function: .fmi_export)."""
    functions: list[ca.Function] = []
    known_syms: list[ca.MX] = []
    if em.initial is not None:
        init = em.initial
        known_syms = list(init.knowns)
        nz, nk = len(init.unknowns), len(known_syms)
        z = ca.MX.sym("z", nz)
        wk = ca.MX.sym("wk", nk)
        g = ca.substitute([ca.vertcat(*init.residual)], init.unknowns + known_syms,
                          [z[i] for i in range(nz)] + [wk[i] for i in range(nk)])[0]
        residual = ca.Function("tbx_init_residual", [z, wk], [g])
        z0 = ca.MX.sym("z0", nz)
        if init.solution:  # block by block (FlatTranslator._initial_system)
            zsol = ca.substitute([ca.vertcat(*init.solution)], init.guesses + known_syms,
                                 [z0[i] for i in range(nz)] + [wk[i] for i in range(nk)])[0]
        else:
            newton = ca.rootfinder("tbx_init_newton", "fast_newton", {"x": z, "p": wk, "g": g},
                                   {"abstol": 1e-12, "max_iter": 100})
            zsol = newton(z0, wk)
        functions.append(ca.Function("tbx_init", [z0, wk], [zsol, residual(zsol, wk)]))
    return functions, known_syms


def _event_function(em: ExplicitModel, quiet: ca.MX) -> tuple[ca.Function, ca.Function, list[ca.MX], int]:
    """``tbx_event(w, quiet) -> out``: one pass of the event iteration (.events). *w* are the values
    of the symbols it reads (as the FMU holds them, pre(v) its held pre value), *out* the new values
    of ``events.updates`` in order, then of the re-initialised states, then each sample's start and
    interval. ``tbx_event_given(w, quiet)``, with the same inputs and outputs, takes the relations'
    values as the FMU holds them instead of recomputing them (the search for a consistent set of
    relations). Returns both functions, their input symbols and the number of updates."""
    ev = em.events
    conditions = {c.sym.name() for c in ev.conditions}

    def body_of(given: bool) -> ca.MX:
        olds: list[ca.MX] = []
        news: list[ca.MX] = []
        for lhs, expr in ev.updates:
            if given and lhs.name() in conditions:
                value = lhs
            else:
                value = ca.substitute([expr], olds, news)[0] if olds else expr
            olds.append(lhs)
            news.append(value)
        reinit = [ca.substitute([e], olds, news)[0] if olds else e for _, e in ev.reinits]
        timing = [smp.start for smp in ev.samples] + [smp.interval for smp in ev.samples]
        outs = news + reinit + timing
        return ca.vertcat(*outs) if outs else ca.MX(0, 1)

    bodies = [body_of(False), body_of(True)]
    seen: dict[str, ca.MX] = {}
    for body in bodies:
        for sym in ca.symvar(body):
            if sym.name() != quiet.name():
                seen.setdefault(sym.name(), sym)
    syms = [seen[n] for n in sorted(seen)]
    w = ca.MX.sym("w", len(syms))
    q = ca.MX.sym("q")
    position = {sym.name(): i for i, sym in enumerate(syms)}
    out = []
    for body in bodies:
        args = ca.symvar(body)
        vals = [w[position[a.name()]] if a.name() in position else q for a in args]
        out.append(ca.substitute([body], args, vals)[0] if args else body)
    n_updates = len(ev.updates)
    return (ca.Function("tbx_event", [w, q], [out[0]]), ca.Function("tbx_event_given", [w, q], [out[1]]),
            syms, n_updates)


def add_runtime(em: ExplicitModel, wrapper: Path, tmpdir: Path, refs: dict[str, int]) -> str:
    """Generate ``tbx_runtime.c`` and patch the wrapper to call it; return the new source's name."""
    functions, known_syms = _runtime_functions(em)
    ev = em.events
    if ev is not None:
        quiet = ca.MX.sym("_tbx_quiet")
        event_fn, given_fn, event_syms, n_updates = _event_function(em, quiet)
        functions += [event_fn, given_fn]
    name = "tbx_runtime.c"
    gen = ca.CodeGenerator(name, {"with_header": False})
    for fn in functions:
        gen.add(fn)
    gen.generate(str(tmpdir) + os.sep)
    by_name = {fn.name(): fn for fn in functions}

    asserts = fmu_asserts(em)
    n_assert = len(asserts)
    glue = [_COMMON]
    if em.asserts:
        glue.append(f"#define TBX_N_ASSERT {n_assert}\n")
        glue.append(_c_array("long", "tbx_a_vr", [str(refs[f"_tbx_a{k + 1}"]) for k in range(n_assert)]))
        glue.append(_c_array("char*", "tbx_a_message", [_c_string(a.message) for a in asserts]))
        glue.append(_c_array("int", "tbx_a_error", ["1" if a.level == "error" else "0" for a in asserts]))
        glue.append(_ASSERTS)
    if em.initial is not None:
        init = em.initial
        fn = by_name["tbx_init"]
        glue.append(f"#define TBX_I_NZ {len(init.unknowns)}\n#define TBX_I_NK {len(known_syms)}\n"
                    f"#define TBX_I_TOL {INIT_TOLERANCE!r}\n")
        glue.append(_work_defines("TBX_I", fn))
        glue.append("int tbx_init(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, "
                    "int mem);\nint tbx_init_checkout(void);\nvoid tbx_init_release(int mem);\n")
        glue.append(_c_array("long", "tbx_i_unknown_vr", _vrs(init.unknowns, refs, em.name, "the initial equations")))
        glue.append(_c_array("long", "tbx_i_known_vr", _vrs(known_syms, refs, em.name, "the initial equations")))
        glue.append(_c_array("char*", "tbx_i_origin", [_c_string(o) for o in init.origins]))
        glue.append(_c_array("char*", "tbx_i_name", [_c_string(u.name()) for u in init.unknowns]))
        glue.append(_CALL % {"fn": "tbx_init", "P": "TBX_I"})
        glue.append(_INIT)

    n_z = len(ev.indicators) if ev is not None else 0
    if ev is not None:
        fn = by_name["tbx_event"]
        n_out = fn.size1_out(0)
        glue.append(f"#define TBX_E_NW {len(event_syms)}\n#define TBX_E_NU {n_updates}\n"
                    f"#define TBX_E_NR {len(ev.reinits)}\n#define TBX_E_NS {len(ev.samples)}\n"
                    f"#define TBX_E_NOUT {max(n_out, 1)}\n#define TBX_E_MAXIT {MAX_EVENT_ITERATIONS}\n"
                    f"#define TBX_CHATTER_N {CHATTER_EVENTS}\n#define TBX_CHATTER_DT {CHATTER_SPACING!r}\n"
                    f"#define TBX_E_INIT_VR {refs[ev.initial.name()]}\n#define TBX_NZ {n_z}\n")
        glue.append(_work_defines("TBX_E", fn))
        glue.append("int tbx_event(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, "
                    "int mem);\nint tbx_event_checkout(void);\nvoid tbx_event_release(int mem);\n")
        glue.append(_c_array("long", "tbx_e_vr", _vrs(event_syms, refs, em.name, "the event iteration")))
        glue.append(_c_array("long", "tbx_e_upd_vr", _vrs([lhs for lhs, _ in ev.updates], refs, em.name,
                                                          "the event iteration")))
        glue.append(_c_array("long", "tbx_e_reinit_vr", _vrs([x for x, _ in ev.reinits], refs, em.name, "reinit")))
        pres = ev.pres()
        glue.append(f"#define TBX_E_NP {len(pres)}\n")
        glue.append(_c_array("long", "tbx_e_pre_vr", _vrs([p for p, _, _ in pres], refs, em.name, "pre()")))
        glue.append(_c_array("long", "tbx_e_pre_of_vr", _vrs([v for _, v, _ in pres], refs, em.name, "pre()")))
        glue.append(_c_array("long", "tbx_e_sample_vr", _vrs([smp.sym for smp in ev.samples], refs, em.name,
                                                             "sample()")))
        glue.append(_c_array("fmi3ValueReference", "tbx_z_vr",
                             [str(refs[f"_tbx_z{k + 1}"]) for k in range(n_z)]))
        first, at = [], 0  # each relation's indicator (index into tbx_z_vr), -1 for a rounding
        for c in ev.conditions:
            first.append(str(at) if c.kind == "rel" and len(c.indicators) == 1 else "-1")
            at += len(c.indicators)
        glue.append(_c_array("int", "tbx_c_z", first))
        glue.append(_work_defines("TBX_G", by_name["tbx_event_given"]))
        glue.append("int tbx_event_given(const casadi_real** arg, casadi_real** res, casadi_int* iw, "
                    "casadi_real* w, int mem);\nint tbx_event_given_checkout(void);\n"
                    "void tbx_event_given_release(int mem);\n")
        glue.append(f"#define TBX_E_NC {len(ev.conditions)}\n#define TBX_E_PASSES {EVENT_PASSES}\n"
                    f"#define TBX_E_SEARCH {SEARCH_RELATIONS}\n")
        glue.append(_CALL % {"fn": "tbx_event", "P": "TBX_E"})
        glue.append(_CALL % {"fn": "tbx_event_given", "P": "TBX_G"})
        glue.append(_EVENTS)

    exit_body = ["  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;\n"]
    if ev is not None:
        exit_body.append("  if (tbx_initialize_events(m) != fmi3OK) return fmi3Error;\n")
    elif em.initial is not None:
        exit_body.append("  if (tbx_initialize(m) != fmi3OK) return fmi3Error;\n")
    exit_body.append("  return tbx_check_asserts(m);\n" if em.asserts else "  (void)m;\n  return fmi3OK;\n")
    check = "  return tbx_check_asserts((casadi_fmi_memory*)instance);\n" if em.asserts else \
            "  (void)instance;\n  return fmi3OK;\n"
    enter_ct = check
    if ev is not None and ev.samples:  # a sample() instant is over: its conditions fall (no when fires)
        enter_ct = ("  casadi_fmi_memory* m = (casadi_fmi_memory*)instance;\n  int changed = 0;\n"
                    "  if (tbx_samples_on(m) && tbx_event_iteration(m, 1, &changed) != fmi3OK) return fmi3Error;\n"
                    + ("  return tbx_check_asserts(m);\n" if em.asserts else "  return fmi3OK;\n"))

    text = wrapper.read_text()
    patches = [
        ("  const char* instance_name;\n",
         "  const char* instance_name;\n  // trackingbox runtime: FMI logger and assert warning flags\n"
         "  fmi3LogMessageCallback tbx_logger;\n  fmi3InstanceEnvironment tbx_env;\n"
         f"  int tbx_warned[{max(n_assert, 1)}];\n  int tbx_pending;\n"
         "  double tbx_next;\n  int tbx_next_defined;\n  double tbx_last_event;\n  int tbx_burst;\n"),
        ("    m->instance_name = instanceName;\n",
         "    m->instance_name = instanceName;\n    m->tbx_logger = logMessage;\n"
         "    m->tbx_env = instanceEnvironment;\n"),
        ("  // Zero index is negative: No event\n",
         f"  for (i = 0; i < {max(n_assert, 1)}; ++i) m->tbx_warned[i] = 0;\n  m->tbx_pending = -1;\n"
         "  m->tbx_next = 0;\n  m->tbx_next_defined = 0;\n  m->tbx_last_event = 0;\n  m->tbx_burst = -1;\n"
         "  // Zero index is negative: No event\n"),
        ("FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {\n",
         "".join(glue) + "FMI3_Export fmi3Status fmi3Reset(fmi3Instance instance) {\n"),
        ("FMI3_Export fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n  // Unused variables\n"
         "  (void)instance;  // unused\n  // Always successful return\n  return fmi3OK;\n}\n",
         "FMI3_Export fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {\n"
         + "".join(exit_body) + "}\n"),
        ("FMI3_Export fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {\n  // Unused variables\n"
         "  (void)instance;  // unused\n  // Always successful return\n  return fmi3OK;\n}\n",
         "FMI3_Export fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {\n" + enter_ct + "}\n"),
        ("  // We should not need this as there are no internal iterations\n  return fmi3OK;\n",
         "  (void)noSetFMUStatePriorToCurrentPoint;\n  if (enterEventMode) *enterEventMode = fmi3False;\n"
         "  if (terminateSimulation) *terminateSimulation = fmi3False;\n" + check),
    ]
    if em.asserts:
        patches.append((
            "  return fmi3GetFloat64(instance, xdot_vr, N_X, derivatives, N_X);\n",
            "  fmi3Status status = fmi3GetFloat64(instance, xdot_vr, N_X, derivatives, N_X);\n"
            "  if (status == fmi3OK) tbx_note_asserts((casadi_fmi_memory*)instance);\n  return status;\n"))
    if ev is not None:
        patches.append(("  if (nEventIndicators) *nEventIndicators = N_ZERO;\n",
                        "  if (nEventIndicators) *nEventIndicators = TBX_NZ;\n"))
        for func, replacement in (("fmi3GetEventIndicators", _EVENT_INDICATORS),
                                  ("fmi3UpdateDiscreteStates", _UPDATE_DISCRETE)):
            found = re.search(rf"FMI3_Export fmi3Status {func}\(.*?\n}}\n", text, re.S)
            if found is None:
                raise CompileError(f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): {func} "
                                   "not found; the embedded path is pinned to casadi 3.8.2")
            text = text[:found.start()] + replacement + text[found.end():]
    for old, new in patches:
        if text.count(old) != 1:
            raise CompileError(
                f"unexpected CasADi FMU wrapper {wrapper.name} (casadi {ca.__version__}): "
                f"{old.strip().splitlines()[0]!r} not found once; the embedded path is pinned to casadi 3.8.2")
        text = text.replace(old, new)
    wrapper.write_text(text)
    return name


def add_build_source(build_description: Path, source: str) -> None:
    if not build_description.exists():
        return
    root = ET.fromstring(build_description.read_text())
    for file_set in root.iter("SourceFileSet"):
        ET.SubElement(file_set, "SourceFile", {"name": source})
    ET.indent(root, space="    ")
    build_description.write_text('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
