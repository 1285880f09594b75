"""Names of the anthropometric feature points shared by capture, tracking, fit and mesh stages.

The actor/model frame used across the project: metres, right-handed, +x towards the
actor's LEFT, +y up, +z out of the face (towards a camera in front), origin at the
pronasale (nose tip) of the neutral face.  Suffix ``_L``/``_R`` is the actor's own left/right.
"""

#: SPEC Table 2.2 feature points (seed 004), left/right where bilateral.
FEATURE_POINTS: tuple[str, ...] = (
    "glabella",
    "ex_L",  # exocanthion: outer eye corner
    "ex_R",
    "pi_L",  # palpebrale inferius: lowest point of the lower eyelid
    "pi_R",
    "pronasale",  # nose tip
    "al_L",  # alare: nose wing
    "al_R",
    "cphs_L",  # crista philtri superior: top of the philtrum ridge
    "cphs_R",
    "cphi_L",  # crista philtri inferior: bottom of the philtrum ridge
    "cphi_R",
    "ch_L",  # cheilion: mouth corner
    "ch_R",
    "cheek_L",
    "cheek_R",
)

#: The landmarks of the seed's symmetry cost (SPEC eqs 4.38-4.39), per side, measured from ch.
SYMMETRY_LANDMARKS: tuple[str, ...] = ("ex", "pi", "al", "cphi")


def mirror_name(name: str) -> str:
    """Bilateral twin of a feature-point name (``ex_L`` <-> ``ex_R``); others unchanged."""
    if name.endswith("_L"):
        return name[:-2] + "_R"
    if name.endswith("_R"):
        return name[:-2] + "_L"
    return name
