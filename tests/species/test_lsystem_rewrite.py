"""Specification of L-system rewriting: known strings, parameters, conditions, stochastic rules, rejections."""
import numpy as np
import pytest

from species.errors import ParameterError
from species.lsystem.rewrite import GrammarError, LSystem, format_modules, parse_rule, rewrite

THESIS_RULE = ["X -> F[-X][+X]"]
THESIS_STRINGS = {
    1: "F[-X][+X]",
    2: "F[-F[-X][+X]][+F[-X][+X]]",
    3: "F[-F[-F[-X][+X]][+F[-X][+X]]][+F[-F[-X][+X]][+F[-X][+X]]]",
}


@pytest.mark.parametrize("iterations", [1, 2, 3])
def test_thesis_example_gives_the_printed_strings(iterations):
    modules = rewrite("X", THESIS_RULE, iterations, np.random.default_rng(0))
    assert format_modules(modules) == THESIS_STRINGS[iterations]


@pytest.mark.parametrize("iterations, f_count", [(1, 1), (2, 3), (3, 7)])
def test_thesis_example_f_counts_double_plus_one(iterations, f_count):
    modules = rewrite("X", THESIS_RULE, iterations, np.random.default_rng(0))
    assert sum(symbol == "F" for symbol, _ in modules) == f_count


def test_zero_iterations_return_the_axiom():
    assert format_modules(rewrite("F[+X]", THESIS_RULE, 0, np.random.default_rng(0))) == "F[+X]"


def test_parametric_rule_evaluates_arguments_with_constants():
    modules = rewrite("A(2)", ["A(l) -> F(l)A(l*r)"], 3, np.random.default_rng(0), {"r": 0.5})
    assert modules == [("F", (2.0,)), ("F", (1.0,)), ("F", (0.5,)), ("A", (0.25,))]


def test_condition_selects_between_rules():
    rules = ["A(l) : l > 1 -> F(l)A(l-1)", "A(l) : l <= 1 -> L"]
    modules = rewrite("A(3)", rules, 5, np.random.default_rng(0))
    assert format_modules(modules) == "F(3)F(2)L"


def test_module_without_applicable_rule_is_copied():
    modules = rewrite("A(0)B", ["A(l) : l > 1 -> F"], 2, np.random.default_rng(0))
    assert format_modules(modules) == "A(0)B"


def test_rule_matches_only_its_arity():
    modules = rewrite("F F(2)", ["F -> FF"], 1, np.random.default_rng(0))
    assert format_modules(modules) == "FFF(2)"


STOCHASTIC = ["F -> F[+F]F[-F]F : 0.33", "F -> F[+F]F : 0.33", "F -> F[-F]F : 0.34"]


def test_stochastic_rules_repeat_with_the_same_seed():
    first = rewrite("F", STOCHASTIC, 4, np.random.default_rng(7))
    second = rewrite("F", STOCHASTIC, 4, np.random.default_rng(7))
    assert first == second


def test_stochastic_rules_differ_between_seeds():
    strings = {format_modules(rewrite("F", STOCHASTIC, 4, np.random.default_rng(seed))) for seed in range(5)}
    assert len(strings) > 1


def test_stochastic_choice_follows_weights():
    rules = ["A -> B : 3", "A -> C : 1"]
    modules = rewrite("A" * 4000, rules, 1, np.random.default_rng(0))
    share_b = sum(symbol == "B" for symbol, _ in modules) / len(modules)
    assert 0.72 < share_b < 0.78


@pytest.mark.parametrize("rule, problem", [
    ("X => F", "'->'"),
    ("X -> F -> G", "'->'"),
    ("XY -> F", "exactly one module"),
    ("X -> F[+X", "unclosed '['"),
    ("X -> F]", "closes no '['"),
    ("A(l) -> F(l*q)", "'q'"),
    ("A(l) -> F(__import__('os'))", "calls something other than"),
    ("A(l) -> F(l.real)", "Attribute"),
    ("X -> F(1,2)", "at most 1"),
    ("X -> F : 0", "weight"),
    ("X -> F#", "'#'"),
])
def test_malformed_rule_is_rejected_naming_the_rule(rule, problem):
    with pytest.raises(GrammarError) as caught:
        LSystem.parse("X", [rule])
    assert repr(rule) in str(caught.value) and problem in str(caught.value)


def test_grammar_error_is_a_parameter_error_for_the_cli():
    with pytest.raises(ParameterError):
        parse_rule("nonsense")


def test_runaway_growth_stops_with_an_error_naming_iterations():
    with pytest.raises(ParameterError, match="iterations"):
        rewrite("F", ["F -> FFFF"], 20, np.random.default_rng(0), max_modules=10_000)


def test_arithmetic_failure_names_the_rule():
    with pytest.raises(GrammarError, match="A\\(l\\) -> F\\(1/l\\)"):
        rewrite("A(0)", ["A(l) -> F(1/l)"], 1, np.random.default_rng(0))
