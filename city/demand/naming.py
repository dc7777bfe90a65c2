"""The names a synthetic world gives its venues, home teams and flagship shows.

The ``nyc``, ``manhattan`` and ``synthetic`` scenarios keep New York's names
(:data:`NEW_YORK`: the Knicks at the Garden Arena, the NY Tech Expo at the
Hudson Convention Center), which their published results and trained
predictors were made with.  Any other city gets :func:`neutral` names built
from its own name ("Gridville Arena", "Gridville Comets vs. Riverton
Hawks", "Gridville Tech Expo"), so an invented or foreign city never hosts
New York's teams.  A scenario file chooses with ``event_names``.

Both namings have lists of the same lengths, so a world draws the same
random numbers, and the same events, whichever it uses: only the words differ.
"""

from __future__ import annotations

from dataclasses import dataclass

from city import texts
from city.errors import ConfigError

NAMINGS = ("new-york", "neutral")

_NY_THEATRES = (
    "Gershwin", "Majestic", "Imperial", "Shubert", "Booth", "Barrymore", "Belasco", "Ambassador", "Lyceum", "Hudson",
    "Palace", "Lunt", "Winter", "Minskoff", "Richard", "August", "Walter", "Eugene", "Neil", "Samuel", "Helen",
    "Hayes", "Nederlander", "Broadhurst", "Golden", "Jacobs", "Longacre", "Marquis", "Cort", "Stein", "Hirschfeld",
    "Lyric", "Vivian", "Circle", "Studio", "Friedman", "Music Box", "Schoenfeld", "Brooks", "Todd",
)
_NEUTRAL_THEATRES = (
    "Majestic", "Imperial", "Lyric", "Palace", "Orpheum", "Paramount", "Regent", "Royal", "Alhambra", "Empire",
    "Capitol", "Rialto", "Grand", "Victoria", "Strand", "Bijou", "Coronet", "Colonial", "Tivoli", "Riviera",
    "Apollo", "Crown", "Embassy", "Garrick", "Savoy", "Globe", "Liberty", "Odeon", "Pantages", "State",
    "Avalon", "Fox", "Harmony", "Jewel", "Keystone", "Lantern", "Monarch", "Pioneer", "Summit", "Union",
)
#: Invented towns for visiting teams; none is a real league's.
_TOWNS = (
    "Riverton", "Bayport", "Lakemont", "Eastfield", "Highmoor", "Stonebridge", "Fairhaven", "Northgate",
    "Cedar Falls", "Westbrook", "Millbrook", "Oakridge", "Pinecrest", "Redcliff", "Silverlake", "Ashford",
)
_MASCOTS = {"basketball": "Hawks", "hockey": "Blades", "wnba": "Flames", "college": "Owls"}
_HOME = {"basketball": "Comets", "hockey": "Ironmen", "wnba": "Sparks", "college": "Scholars"}
_NY_SPECIALS = {"Harlem Exhibition Game": "Exhibition Game", "Big East Tournament": "College Basketball Tournament"}
_NY_SHOWS = {"New York, New York": "Singin' in the Rain"}


@dataclass(frozen=True)
class Naming:
    """Every name a synthetic world's calendar uses that could place it in a particular city."""

    arena: str
    convention_center: str
    festival_grounds: str
    pier: str  # format string with ``{n}``
    theatres: tuple[str, ...]
    teams: dict[str, tuple[str, tuple[str, ...]]]
    marquee: frozenset[str]
    specials: tuple[str, ...]
    flagship_expo: str
    eval_rival: str
    shows: dict[str, str]

    def show(self, name: str) -> str:
        """A production's title as this city bills it."""
        return self.shows.get(name, name)


NEW_YORK = Naming(
    arena="Garden Arena", convention_center="Hudson Convention Center", festival_grounds="Riverside Festival Grounds",
    pier="Pier {n}", theatres=_NY_THEATRES, teams=texts.TEAMS, marquee=texts.MARQUEE, specials=texts.SPORTS_SPECIALS,
    flagship_expo="NY Tech Expo", eval_rival="Celtics", shows={},
)


def neutral(city: str) -> Naming:
    """Names built from ``city`` (e.g. ``Gridville``) and invented towns, with the lengths of :data:`NEW_YORK`'s lists."""
    label = city.strip().replace("_", " ").replace("-", " ")
    label = label.title() if label.islower() else label
    teams, marquee = {}, set()
    for sport, (_, rivals) in texts.TEAMS.items():
        mine = tuple(f"{_TOWNS[i % len(_TOWNS)]} {_MASCOTS[sport]}" for i in range(len(rivals)))
        teams[sport] = (f"{label} {_HOME[sport]}", mine)
        marquee |= {m for m, r in zip(mine, rivals) if r in texts.MARQUEE}
    return Naming(
        arena=f"{label} Arena", convention_center=f"{label} Convention Center", festival_grounds=f"{label} Festival Grounds",
        pier="Waterfront Park {n}", theatres=_NEUTRAL_THEATRES, teams=teams, marquee=frozenset(marquee),
        specials=tuple(_NY_SPECIALS.get(s, s) for s in texts.SPORTS_SPECIALS),
        flagship_expo=f"{label} Tech Expo", eval_rival=teams["basketball"][1][texts.TEAMS["basketball"][1].index("Celtics")], shows=_NY_SHOWS,
    )


def naming_for(style: str, city: str) -> Naming:
    """The naming a scenario's ``event_names`` asks for."""
    if style == "new-york":
        return NEW_YORK
    if style == "neutral":
        return neutral(city)
    raise ConfigError(f"event_names must be one of {NAMINGS}, got {style!r}")
