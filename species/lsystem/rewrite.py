"""L-system grammar and rewriting: parametric, bracketed, stochastic rules applied n times to an axiom.

In: an axiom string, rule strings, constants, an rng. Out: a module list [(symbol, params), ...] and its text.

Rule syntax (one string per rule):  PRED[(a, b)] [: condition] -> SUCCESSOR [: weight]
  X -> F[-X][+X]                          plain rule
  A(l, w) : l > 0.1 -> !(w)F(l)[&(30)A(l*r, w)]   parametric with a condition and constants (r)
  F -> F[+F]F : 0.33                      stochastic: rules with the same predecessor compete by weight
A module is one symbol (a letter or one of the turtle symbols) with an optional parenthesised argument list.
Arguments, conditions and weights are arithmetic over the formal parameters, the constants, `pi` and the
functions sqrt, sin, cos, tan, exp, log, abs, min, max, floor, ceil (radians); nothing else can be named.
"""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import ParameterError

__all__ = ["GrammarError", "Rule", "LSystem", "TURTLE_SYMBOLS", "parse_modules", "parse_rule", "format_modules",
           "rewrite", "Module"]

# One module: (symbol, parameter values). Plain tuples keep rewriting of 10^5 modules cheap.
Module = tuple[str, tuple[float, ...]]

# Symbols the turtle interprets, with the most arguments each takes.
TURTLE_SYMBOLS: dict[str, int] = {
    "F": 1, "f": 1, "+": 1, "-": 1, "&": 1, "^": 1, "\\": 1, "/": 1, "|": 0, "[": 0, "]": 0, "!": 1, "L": 1,
}
_FUNCTIONS = {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "exp": math.exp,
              "log": math.log, "abs": abs, "min": min, "max": max, "floor": math.floor, "ceil": math.ceil,
              "pi": math.pi}
_ALLOWED_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.BoolOp, ast.Compare, ast.IfExp, ast.Call,
                  ast.Name, ast.Load, ast.Constant, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.FloorDiv, ast.Mod,
                  ast.Pow, ast.USub, ast.UAdd, ast.Not, ast.And, ast.Or, ast.Eq, ast.NotEq, ast.Lt, ast.LtE,
                  ast.Gt, ast.GtE)
RULE_FORM = "'PRED[(a, b)] [: condition] -> SUCCESSOR [: weight]', e.g. 'X -> F[-X][+X]'"


class GrammarError(ParameterError):
    """An axiom or rule string that does not parse, or a rule whose arithmetic fails; names the text."""

    def __init__(self, key: str, text: str, problem: str):
        self.key, self.value, self.allowed = key, text, RULE_FORM
        ValueError.__init__(self, f"{key} {text!r} is malformed: {problem} (a rule reads {RULE_FORM})")


# ---------------------------------------------------------------- parsing
def _is_symbol(char: str) -> bool:
    return char.isascii() and (char.isalpha() or char in TURTLE_SYMBOLS)


def _split_arguments(text: str) -> list[str]:
    """Split 'a, max(b, c)' at top-level commas."""
    parts, depth, start = [], 0, 0
    for i, char in enumerate(text):
        depth += (char == "(") - (char == ")")
        if char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_modules(text: str, key: str = "axiom", whole: str | None = None) -> list[tuple[str, list[str]]]:
    """Split a module string into (symbol, argument texts).

    Raises GrammarError naming `key` and `whole` (the full rule this text is part of; default `text` itself).
    """
    if not isinstance(text, str):
        raise GrammarError(key, str(text), "not a string")
    where = "" if whole is None else f" in {text.strip()!r}"
    text_named = text if whole is None else whole
    modules: list[tuple[str, list[str]]] = []
    i, n, depth = 0, len(text), 0
    while i < n:
        char = text[i]
        if char.isspace():
            i += 1
            continue
        if not _is_symbol(char):
            raise GrammarError(key, text_named, f"{char!r} at position {i} is not a module symbol "
                                                f"(letters or {''.join(TURTLE_SYMBOLS)}){where}")
        args: list[str] = []
        j = i + 1
        if j < n and text[j] == "(":
            level, k = 0, j
            while k < n:
                level += (text[k] == "(") - (text[k] == ")")
                if level == 0:
                    break
                k += 1
            if k == n:
                raise GrammarError(key, text_named, f"unclosed '(' after {char!r} at position {i}{where}")
            args = _split_arguments(text[j + 1:k])
            if any(a == "" for a in args):
                raise GrammarError(key, text_named, f"empty argument in {text[i:k + 1]!r}{where}")
            j = k + 1
        if char in TURTLE_SYMBOLS and len(args) > TURTLE_SYMBOLS[char]:
            raise GrammarError(key, text_named, f"{char!r} takes at most {TURTLE_SYMBOLS[char]} "
                                                f"argument(s), got {len(args)}{where}")
        depth += (char == "[") - (char == "]")
        if depth < 0:
            raise GrammarError(key, text_named, f"']' at position {i} closes no '['{where}")
        modules.append((char, args))
        i = j
    if depth:
        raise GrammarError(key, text_named, f"{depth} unclosed '['{where}")
    return modules


def _compile_expression(expression: str, names: set[str], key: str, text: str) -> str:
    """Check an expression against the whitelist and return its canonical source."""
    try:
        tree = ast.parse(expression, mode="eval")
    except SyntaxError:
        raise GrammarError(key, text, f"{expression!r} is not an arithmetic expression") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED_NODES):
            raise GrammarError(key, text, f"{expression!r} uses {type(node).__name__}, which is not allowed")
        if isinstance(node, ast.Name) and node.id not in names and node.id not in _FUNCTIONS:
            raise GrammarError(key, text, f"{expression!r} names {node.id!r}; known names: "
                                          f"{', '.join(sorted(names)) or '(none)'} and {', '.join(_FUNCTIONS)}")
        if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS
                                               and not node.keywords):
            raise GrammarError(key, text, f"{expression!r} calls something other than "
                                          f"{', '.join(k for k, v in _FUNCTIONS.items() if callable(v))}")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                               or not isinstance(node.value, (int, float))):
            raise GrammarError(key, text, f"{expression!r} holds {node.value!r}; only numbers are allowed")
        if isinstance(node, ast.Constant):
            node.value = float(node.value)  # so '30' yields 30.0 like every other parameter
    return ast.unparse(tree)


def _lambda(formals: list[str], body: str, constants: dict[str, float]) -> Callable:
    # The body was rebuilt from a whitelisted AST (numbers, names, arithmetic, listed functions), so
    # evaluating it cannot reach anything beyond the namespace given here.
    namespace = {"__builtins__": {}, **_FUNCTIONS, **constants}
    return eval(f"lambda {', '.join(formals)}: {body}", namespace)  # noqa: S307


# ---------------------------------------------------------------- rules
@dataclass(frozen=True)
class Rule:
    """One production. `successor(*params)` returns the replacement modules; `condition` may be None."""

    text: str
    symbol: str
    arity: int
    successor: Callable[..., list[Module]]
    condition: Callable[..., bool] | None
    weight: float


def _split_once(text: str, sep: str) -> tuple[str, str | None]:
    head, found, tail = text.partition(sep)
    return (head, tail) if found else (head, None)


def parse_rule(text: str, constants: dict[str, float] | None = None) -> Rule:
    """Parse one rule string (syntax in the module docstring); raises GrammarError naming the rule."""
    key = "rule"
    constants = dict(constants or {})
    if not isinstance(text, str):
        raise GrammarError(key, str(text), "not a string")
    if text.count("->") != 1:
        raise GrammarError(key, text, "needs exactly one '->' between predecessor and successor")
    left, right = text.split("->")
    pred_text, cond_text = _split_once(left, ":")
    succ_text, weight_text = _split_once(right, ":")
    pred = parse_modules(pred_text, key, text) if pred_text.strip() else []
    if len(pred) != 1 or pred[0][0] in "[]":
        raise GrammarError(key, text, "the predecessor must be exactly one module other than '[' or ']'")
    symbol, formals = pred[0]
    for name in formals:
        if not name.isidentifier() or name in _FUNCTIONS:
            raise GrammarError(key, text, f"formal parameter {name!r} must be a plain name")
    if len(set(formals)) != len(formals):
        raise GrammarError(key, text, "formal parameters repeat a name")
    clash = set(formals) & set(constants)
    if clash:
        raise GrammarError(key, text, f"formal parameter(s) {sorted(clash)} shadow constants of the same name")
    names = set(formals) | set(constants)

    successor_modules = parse_modules(succ_text, key, text)
    items = []
    for succ_symbol, args in successor_modules:
        sources = [_compile_expression(a, names, key, text) for a in args]
        items.append(f"({succ_symbol!r}, ({''.join(s + ', ' for s in sources)}))")
    successor = _lambda(formals, "[" + ", ".join(items) + "]", constants)

    condition = None
    if cond_text is not None and cond_text.strip():
        condition = _lambda(formals, _compile_expression(cond_text.strip(), names, key, text), constants)
    weight = 1.0
    if weight_text is not None:
        weight_source = _compile_expression(weight_text.strip(), set(constants), key, text)
        weight = float(_lambda([], weight_source, constants)())
        if not (math.isfinite(weight) and weight > 0):
            raise GrammarError(key, text, f"weight {weight_text.strip()!r} = {weight} must be a number > 0")
    return Rule(text, symbol, len(formals), successor, condition, weight)


def _evaluate_axiom(text: str, constants: dict[str, float]) -> list[Module]:
    modules = []
    for symbol, args in parse_modules(text, "axiom"):
        values = tuple(float(_lambda([], _compile_expression(a, set(constants), "axiom", text), constants)())
                       for a in args)
        modules.append((symbol, values))
    return modules


# ---------------------------------------------------------------- rewriting
@dataclass(frozen=True)
class LSystem:
    """An axiom with its rules. Build with `LSystem.parse(axiom, rules, constants)`."""

    axiom: tuple[Module, ...]
    rules: dict[tuple[str, int], tuple[Rule, ...]]

    @classmethod
    def parse(cls, axiom: str, rules: list[str], constants: dict[str, float] | None = None) -> "LSystem":
        constants = {k: float(v) for k, v in (constants or {}).items()}
        table: dict[tuple[str, int], list[Rule]] = {}
        for text in rules:
            rule = parse_rule(text, constants)
            table.setdefault((rule.symbol, rule.arity), []).append(rule)
        return cls(tuple(_evaluate_axiom(axiom, constants)), {k: tuple(v) for k, v in table.items()})

    @property
    def stochastic(self) -> bool:
        return any(len(group) > 1 for group in self.rules.values())

    def step(self, modules: list[Module], rng: np.random.Generator) -> list[Module]:
        """Rewrite every module once, in parallel (each module sees the previous generation only)."""
        # One uniform per module, drawn up front, so the draw count depends on the string alone.
        draws = rng.random(len(modules)).tolist() if self.stochastic else None
        rules, out = self.rules, []
        for index, module in enumerate(modules):
            group = rules.get((module[0], len(module[1])))
            if group is None:
                out.append(module)
                continue
            params = module[1]
            try:
                if len(group) == 1 and group[0].condition is None:
                    out.extend(group[0].successor(*params))
                    continue
                live = [r for r in group if r.condition is None or r.condition(*params)]
                if not live:
                    out.append(module)
                    continue
                chosen = live[0]
                if len(live) > 1:
                    target = draws[index] * sum(r.weight for r in live)
                    for chosen in live:
                        target -= chosen.weight
                        if target < 0:
                            break
                out.extend(chosen.successor(*params))
            except (ArithmeticError, ValueError, TypeError) as error:
                raise GrammarError("rule", group[0].text,
                                   f"evaluating it on {format_modules([module])} failed: {error}") from None
        return out

    def derive(self, iterations: int, rng: np.random.Generator, max_modules: int = 500_000) -> list[Module]:
        """The string after `iterations` rewriting steps; raises if it outgrows `max_modules`."""
        modules = list(self.axiom)
        for iteration in range(iterations):
            modules = self.step(modules, rng)
            if len(modules) > max_modules:
                raise ParameterError("iterations", iterations,
                                     f"at most {iteration} for this grammar: iteration {iteration + 1} makes "
                                     f"{len(modules)} modules, over the limit of {max_modules}")
        return modules


def rewrite(axiom: str, rules: list[str], iterations: int, rng: np.random.Generator,
            constants: dict[str, float] | None = None, max_modules: int = 500_000) -> list[Module]:
    """Parse and derive in one call: the module list after `iterations` steps."""
    return LSystem.parse(axiom, rules, constants).derive(iterations, rng, max_modules)


def _format_number(value: float) -> str:
    return f"{value:.6g}"


def format_modules(modules: list[Module]) -> str:
    """The text of a module list: 'F(1.2)+(30)[X]'; parameterless modules print as their bare symbol."""
    return "".join(symbol + ("(" + ",".join(map(_format_number, params)) + ")" if params else "")
                   for symbol, params in modules)
