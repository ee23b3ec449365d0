"""The registry of solvers: how pcg resolves, how each type reaches a control, each rule
stated once and worded by the scene and by petgap.solve with their own keys, and the
settings of a solve read once from the keywords and the PETSc options."""
import pytest

from petgap.io import solver_registry as registry
from petgap.io.scene import Scene, SceneError, SolverSection, _keys
from petgap.io.solver_registry import Case, method, refusal, resolve
from petgap.solvers.dispatch import petsc_options
from petgap.solvers.settings import SolverSettings, read_settings

SCENE = '[grid]\nnx = 16\n[surface]\nhurst = 0.6\nlambda_min = "4 a0"\n'


@pytest.mark.parametrize("control, adhesive, periodic, precision, kind", [
    ("load", False, True, "double", "pcg-pressure"),
    ("mean-gap", False, True, "double", "pcg-gap"),
    ("mean-gap", False, True, "mixed", "pcg-pressure"),
    ("mean-gap", False, False, "double", "pcg-pressure"),
    ("indentation", False, False, "double", "pcg-pressure"),
    ("load", True, True, "double", "pcg-gap"),
    ("load", True, False, "double", "pcg-gap"),
])
def test_pcg_resolves_to_the_formulation_that_suits(control, adhesive, periodic, precision,
                                                     kind):
    assert resolve("pcg", control, adhesive, periodic, precision) == kind
    assert resolve("bncg", control, adhesive, periodic, precision) == "bncg"


@pytest.mark.parametrize("kind, control, periodic, how", [
    ("pcg-pressure", "load", True, "direct"),
    ("pcg-pressure", "mean-gap", False, "indentation"),
    ("pcg-gap", "load", True, "direct"),
    ("pcg-gap", "mean-gap", False, "padded cell"),
    ("blmvm", "mean-gap", True, "multiplier"),
    ("blmvm", "load", False, "padded cell"),
])
def test_how_each_type_reaches_a_control(kind, control, periodic, how):
    assert method(kind, control, periodic) == how


def test_the_schema_offers_what_the_registry_lists():
    keys = _keys(SolverSection)
    assert keys["tao_type"].type.choices == registry.SOLVER_NAMES
    assert keys["precision"].type.choices == registry.PRECISIONS


ADHESIVE = '[interaction]\nkind = "exponential"\nwork_of_adhesion = 1e-3\nrange = 1.0\n'


@pytest.mark.parametrize("free, scene, case, scene_key, api_key", [
    (False, ADHESIVE + '[solver]\nprecision = "mixed"\n',
     Case("pcg", "load", True, True, "mixed"), 'solver.precision = "mixed"',
     "precision 'mixed'"),
    (True, '[control]\nkind = "indentation"\nvalues = 1.0\n[solver]\ntao_type = "bncg"\n',
     Case("bncg", "indentation", False, False, "double"), 'solver.tao_type = "bncg"',
     "solver 'bncg'"),
    (False, '[control]\nkind = "indentation"\nvalues = 1.0\n',
     Case("pcg", "indentation", False, True, "double"), 'control.kind = "indentation"',
     "indentation control"),
    (False, ADHESIVE + '[solver]\ntao_type = "pcg-pressure"\n',
     Case("pcg-pressure", "load", True, True, "double"), 'solver.tao_type = "pcg-pressure"',
     "solver 'pcg-pressure'"),
    (False, '[control]\nkind = "load"\nvalues = [0.01, -0.02]\n',
     Case("pcg", "load", False, True, "double", loads=(0.01, -0.02)),
     "control.values = [0.01, -0.02]: item 1 (-0.02)", "load -0.02"),
])
def test_one_rule_one_message_in_each_layers_words(comm, free, scene, case, scene_key,
                                                    api_key):
    """The scene and petgap.solve word the same rule with the registry's words, each
    naming the input by its own key."""
    surface = SCENE.replace("[surface]\n", "[surface]\nperiodic = false\n") if free else SCENE
    with pytest.raises(SceneError) as info:
        Scene.from_text(surface + scene, comm)
    refused = refusal(case)
    message, scene_message = refused.message(), str(info.value)
    assert message.startswith(f"{api_key} {refused.problem}"), message
    assert f"{scene_key}" in scene_message and refused.problem in scene_message, scene_message
    assert f"allowed: {refused.allowed}" in message
    assert f"allowed: {refused.allowed}" in scene_message


def test_the_settings_are_read_once_from_keywords_and_options():
    settings = read_settings("double", solver="pcg-gap", tolerance=1e-6, max_iterations=7)
    assert settings == SolverSettings(tolerance=1e-6, max_iterations=7, solver="pcg-gap")
    with petsc_options({"tao_type": "python", "petgap_coarse_start": "0",
                        "petgap_edge_correction": "0.25", "petgap_interaction_block": "0"}):
        settings = read_settings("double", solver="bncg", precision="mixed")
    assert (settings.solver, settings.precision, settings.coarse_start) == \
        ("pcg", "mixed", False)
    assert (settings.edge_correction, settings.interaction_block) == (0.25, 0)
    assert settings.search_precision == "single"    # a mixed solve searches in single
    assert read_settings("single").precision == "single"   # the grid's, by default
    with petsc_options({"tao_type": "lbfgs"}), pytest.raises(ValueError, match=(
            r"-tao_type 'lbfgs' is not one of pcg, pcg-pressure")):
        read_settings("double")
    with pytest.raises(ValueError, match="solver 'bncgg' is not one of pcg"):
        SolverSettings(solver="bncgg")


def test_a_control_object_in_the_registrys_words_and_the_check_that_raises():
    from petgap.mechanics.problem import Indentation, Load, MeanGap  # deferred: this test only
    assert registry.control_words(Load(-0.5)) == {"control": "load", "loads": (-0.5,)}
    assert registry.control_words(MeanGap(1.0)) == {"control": "mean-gap", "loads": ()}
    assert registry.control_words(Indentation(0.2)) == {"control": "indentation", "loads": ()}
    registry.check(Case(solver="pcg", adhesive=True, periodic=True,
                        **registry.control_words(Load(-0.5))))
    with pytest.raises(ValueError, match=r"load -0.5 is tensile.*allowed: a load >= 0"):
        registry.check(Case(solver="pcg", adhesive=False, periodic=True,
                            **registry.control_words(Load(-0.5))))


@pytest.mark.parametrize("precision", ["single", "mixed"])
def test_adhesive_scene_in_single_or_mixed_is_refused_with_the_reason(comm, precision):
    """A scene with an interaction and ``solver.precision`` other than double is refused
    naming the key, the reason (adhesion in double only, docs/accuracy.md) and what is
    allowed; the same scene in double is accepted."""
    with pytest.raises(SceneError) as info:
        Scene.from_text(SCENE + ADHESIVE + f'[solver]\nprecision = "{precision}"\n', comm)
    message = str(info.value)
    assert f'solver.precision = "{precision}"' in message, message
    assert "adhesion is solved in double only" in message and "docs/accuracy.md" in message
    assert "allowed: double" in message, message
    scene = Scene.from_text(SCENE + ADHESIVE + '[solver]\nprecision = "double"\n', comm)
    assert scene.solver.precision == "double" and scene.interaction.kind == "exponential"
