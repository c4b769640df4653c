"""The shipped verifier parameters (config/): the template and the overrides, loaded in that
order (config/rover_template.yaml, then config/rover_<environment>.yaml), as every host loads
them: the launch files (two <rosparam> loads into one namespace), rover_replay (--config TEMPLATE
--config OVERRIDE, applied in command-line order) and the benchmarks (bench.shipped()).

Keys without effect at the shipped defaults are not set in the files but named in comments
("# key: value" lines): the template's last block (the core's defaults), and an override's
"with decision: chi2 or revisit" block (what that environment runs those decisions with;
shipped() applies it when --decision chi2|revisit is asked for)."""
import os
import re

import yaml

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", ".."))
CONFIG = os.path.join(ROOT, "config")
TEMPLATE = os.path.join(CONFIG, "rover_template.yaml")
ENVIRONMENTS = ("indoor", "outdoor", "paper")
NOT_SET_MARKER = "# ==== not set here"
OPT_IN_MARKER = "# ---- with decision: chi2 or revisit"
OPT_IN_DECISIONS = ("chi2", "revisit")


def override_path(environment):
    """config/rover_<environment>.yaml: the keys of `environment` that differ from the template."""
    return os.path.join(CONFIG, f"rover_{environment}.yaml")


def files(environment):
    """The files a host loads for `environment`, in order."""
    return [TEMPLATE, override_path(environment)]


def replay_args(environment):
    """rover_replay flags that load `environment`'s files (later flags override them)."""
    args = []
    for f in files(environment):
        args += ["--config", f]
    return args


def load(path):
    """The keys a file sets (a dict; {} for one with comments only)."""
    with open(path) as f:
        return yaml.safe_load(f) or {}


def commented(path, marker):
    """The "# key: value" lines of `path` after the line that starts with `marker`, as a dict."""
    out, inside = {}, False
    with open(path) as f:
        for line in f:
            if line.startswith(marker):
                inside = True
            elif inside and not line.startswith("#"):
                break
            elif inside:
                m = re.match(r"# ([a-z_0-9]+): ([^\s#]+)(\s+#.*)?$", line.rstrip("\n"))
                if m:
                    out[m.group(1)] = yaml.safe_load(m.group(2))
    return out


def defaults():
    """The template's keys that are not set, at the defaults it names (the core's)."""
    return commented(TEMPLATE, NOT_SET_MARKER)


def opt_in(environment):
    """What `environment` runs decisions chi2 and revisit with beyond the files' keys."""
    return commented(override_path(environment), OPT_IN_MARKER)


def effective(environment, decision=None):
    """Every parameter `environment` runs with (but the host-set ones), as a dict: the template's
    defaults, the template, the override and, for decision chi2 or revisit, the override's
    opt-in block."""
    c = dict(defaults())
    c.update(load(TEMPLATE))
    c.update(load(override_path(environment)))
    if decision is not None:
        c["decision"] = decision
    if c["decision"] in OPT_IN_DECISIONS:
        c.update(opt_in(environment))
    return c


def opt_in_args(environment, args):
    """rover_replay flags of `environment`'s opt-in block when `args` (flags) ask for --decision
    chi2 or revisit, else []."""
    args = [str(a) for a in args]
    decisions = [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--decision"]
    if not decisions or decisions[-1] not in OPT_IN_DECISIONS:
        return []
    out = []
    for k, v in opt_in(environment).items():
        out += ["--" + k, str(v).lower() if isinstance(v, bool) else str(v)]
    return out
