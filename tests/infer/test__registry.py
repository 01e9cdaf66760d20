"""The name -> class registry behind the prior and likelihood registries."""

import pytest

from hubsgo_ppl.infer._registry import build, make_register


def test_register_and_build_with_checked_parameters():
    table: dict[str, type] = {}
    register = make_register(table, "widget", "run")

    @register("box")
    class Box:
        def __init__(self, graph, size=1, colour="red"):
            self.graph, self.size, self.colour = graph, size, colour

        def run(self):
            return self.size

    assert table == {"box": Box} and Box.registered_name == "box"
    assert register("box")(Box) is Box                                  # re-registering the same class is fine
    made = build(table, "widget", "box", "g", size=3)
    assert (made.graph, made.size, made.colour) == ("g", 3, "red")
    with pytest.raises(ValueError, match=r"widget 'box': unknown parameter\(s\) graph, weight; accepted: size, colour"):
        build(table, "widget", "box", "g", weight=2, graph="h")
    with pytest.raises(ValueError, match="unknown widget 'ball'; registered: box"):
        build(table, "widget", "ball")


def test_registration_errors():
    table: dict[str, type] = {}
    register = make_register(table, "prior", "distribution")

    class NoMethod:
        pass

    class A:
        def distribution(self):
            return None

    class B(A):
        pass

    with pytest.raises(ValueError, match="a prior needs a non-empty string name"):
        register("")
    with pytest.raises(TypeError, match="prior NoMethod must define a distribution\\(\\) method"):
        register("x")(NoMethod)
    register("a")(A)
    with pytest.raises(ValueError, match="prior name 'a' is already registered to A; pick another name"):
        register("a")(B)
    assert table == {"a": A}
