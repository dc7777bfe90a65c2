"""Seeded event text: titles, descriptions and reviews, written before the event.

The demand world knows each synthetic event's latent popularity and
sentiment; the predictor only sees text.  Text is written the way real
listings are, *before* the event: the organiser's announcement (title and
description), reviews of the venue, and reviews of the performer's or
production's earlier events at venues like this one.  Nothing here sees the event's realised attendance
(see :mod:`city.demand.attendance`).  The text carries the drivers of
attendance as real listings do:

* the **category** through its own vocabulary (``Broadway musical``,
  ``tip-off``, ``exhibitors``, ``keynote`` …) in titles, descriptions and
  reviews;
* the **venue size** through the venue name and its seat count;
* the **popularity** (ticket sales as the organiser announces them) through
  five tiers of cue phrases (``Sold-Out``, ``Final Week``, ``highly
  anticipated`` … down to ``Community Night``, ``a quiet evening``);
* the performer's **reputation** (what its earlier events drew) through the
  number of reviews (1–100, growing with it) and through crowd, line and
  traffic remarks where such events fill a big venue;
* the **sentiment** through the mixture of positive, neutral and negative
  reviews and a critics' sentence in the description.

Everything draws from a caller's :class:`random.Random`, which is faster
than numpy for many small choices and reproducible across Python versions.
"""

from __future__ import annotations

import datetime as dt
import random

#: Popularity bounds of the five tiers (0 = small and quiet … 4 = sold out).
TIER_BOUNDS: tuple[float, ...] = (0.25, 0.5, 0.7, 0.85)
#: At most this many reviews per event (the paper's Q).
MAX_REVIEWS = 100

# ---------------------------------------------------------------- names
BROADWAY_HITS: tuple[str, ...] = (
    "The Lion King", "Wicked", "Hamilton", "Moulin Rouge!", "MJ the Musical", "Aladdin",
    "The Book of Mormon", "Harry Potter and the Cursed Child", "Six", "Hadestown",
)
BROADWAY_SHOWS: tuple[str, ...] = (
    "Chicago", "The Phantom of the Opera", "Come From Away", "Dear Evan Hansen", "The Music Man",
    "Funny Girl", "Company", "Mrs. Doubtfire", "Kimberly Akimbo", "Into the Woods", "A Strange Loop",
    "Some Like It Hot", "& Juliet", "Les Miserables", "Death of a Salesman", "Leopoldstadt",
    "The Piano Lesson", "Take Me Out", "Plaza Suite", "Macbeth", "Paradise Square", "Beetlejuice",
    "Tina", "Ain't Too Proud", "Almost Famous", "1776", "Kinky Boots", "Topdog/Underdog",
    "Cost of Living", "Mr. Saturday Night", "The Minutes", "POTUS", "American Buffalo",
    "Girl from the North Country", "Ohio State Murders", "Between Riverside and Crazy", "Jagged Little Pill",
    "The Kite Runner", "Camelot", "Parade", "Sweeney Todd", "A Doll's House", "Pictures From Home",
    "Good Night, Oscar", "Shucked", "New York, New York", "Bad Cinderella", "Peter Pan Goes Wrong",
)
SMALL_STAGE: tuple[str, ...] = (
    "An Evening of One-Act Plays", "Improv Night", "Stand-Up Showcase", "Spring Dance Showcase",
    "Chamber Opera Double Bill", "New Works Reading", "Cabaret Night", "Solo Show Series",
    "Contemporary Dance Program", "Puppet Theater Matinee", "Sketch Comedy Revue", "Late-Night Comedy Hour",
)
TEAMS: dict[str, tuple[str, tuple[str, ...]]] = {
    "basketball": ("Knicks", ("Celtics", "Nets", "Heat", "Lakers", "76ers", "Bucks", "Bulls", "Warriors",
                              "Raptors", "Hawks", "Cavaliers", "Magic", "Pistons", "Hornets", "Wizards", "Pacers")),
    "hockey": ("Rangers", ("Islanders", "Devils", "Bruins", "Flyers", "Penguins", "Capitals", "Maple Leafs",
                           "Canadiens", "Lightning", "Hurricanes", "Red Wings", "Sabres", "Senators", "Blue Jackets")),
    "wnba": ("Liberty", ("Sun", "Sky", "Aces", "Storm", "Mystics", "Fever", "Dream", "Wings", "Sparks", "Lynx")),
    "college": ("Red Storm", ("Huskies", "Wildcats", "Blue Devils", "Hoyas", "Orange", "Friars", "Pirates")),
}
#: Opponents that draw bigger crowds (rivalries, stars).
MARQUEE = frozenset({"Celtics", "Nets", "Lakers", "Warriors", "Islanders", "Devils", "Bruins", "Sun", "Aces", "Huskies"})
SPORTS_SPECIALS: tuple[str, ...] = (
    "Championship Boxing Night", "Pro Wrestling Live", "Professional Bull Riders", "Harlem Exhibition Game",
    "Big East Tournament", "College Hoops Showcase", "Figure Skating Spectacular", "Gymnastics Championships",
)
BAND_ADJ: tuple[str, ...] = (
    "Velvet", "Electric", "Midnight", "Golden", "Silver", "Neon", "Wild", "Crimson", "Hollow", "Lucky", "Paper",
    "Northern", "Broken", "Blue", "Static", "Young", "Glass", "Atomic", "Quiet", "Burning", "Lonesome", "Cosmic",
)
BAND_NOUN: tuple[str, ...] = (
    "Lanterns", "Wolves", "Harbors", "Satellites", "Tigers", "Ghosts", "Rivers", "Echoes", "Foxes", "Parade",
    "Machines", "Orchids", "Strangers", "Comets", "Sparrows", "Kings", "Waves", "Saints", "Radios", "Pilots",
)
TOUR_SUFFIX: tuple[str, ...] = ("World Tour", "Live", "Album Release Show", "Reunion Tour", "Acoustic Set", "Farewell Tour", "Residency")
EXPOS: tuple[str, ...] = (
    "NY Tech Expo", "International Auto Show", "Comic Con", "Boat Show", "Home & Garden Expo", "Food & Wine Expo",
    "Bridal Expo", "Travel & Adventure Show", "Toy Fair", "Licensing Expo", "Jewelry Show", "Art Expo",
    "Health & Fitness Expo", "Pet Expo", "Coffee Fest", "Fashion Trade Show", "Gaming Expo", "Real Estate Expo",
    "Restaurant Show", "Beauty Expo", "Photo Plus Expo", "Outdoor Gear Show", "Franchise Expo", "Wine Trade Fair",
)
CONF_TOPICS: tuple[str, ...] = (
    "AI", "Fintech", "Cloud Security", "Healthcare Innovation", "Marketing", "Data Science", "Sustainability",
    "Real Estate", "Blockchain", "Retail", "Media", "Legal Tech", "Biotech", "Education", "Urban Mobility",
    "Insurance", "Supply Chain", "Cybersecurity", "Product Design", "HR Leaders",
)
CONF_FORMATS: tuple[str, ...] = ("Summit", "Conference", "Forum", "Symposium", "World Congress", "Leadership Days")
FESTIVALS: tuple[str, ...] = (
    "Summer Music Festival", "Food Truck Festival", "Jazz Festival", "Film Festival", "Street Fair", "Pride Festival",
    "Dance Festival", "Taste of the City", "Oktoberfest", "Craft Beer Festival", "Book Festival", "Comedy Festival",
    "Lantern Festival", "Hip-Hop Block Festival", "Latin Music Festival", "Kite Festival",
)
WINTER_FESTIVALS: tuple[str, ...] = ("Holiday Market", "Winter Lights Festival", "Tree Lighting", "Lunar New Year Festival")
COMMUNITY: tuple[str, ...] = (
    "Neighborhood Cleanup", "Book Club Meetup", "Community Board Meeting", "Farmers Market", "Open Mic", "Art Walk",
    "Yoga in the Park", "Chess Club", "Poetry Reading", "Blood Drive", "Library Story Time", "Block Party",
    "Volunteer Orientation", "Senior Social", "Language Exchange", "Tenant Association Meeting", "Knitting Circle",
    "Local History Talk", "Coding Workshop", "Gallery Opening",
)

# ---------------------------------------------------------------- cues
_SHOW_CUES: tuple[tuple[str, ...], ...] = (
    ("Community Night", "Free Admission", "Open Rehearsal", ""),
    ("", "", "Weeknight Special"),
    ("", "Live", "Now Playing"),
    ("Limited Engagement", "Extended Run", "Encore Performance", "By Popular Demand"),
    ("Sold-Out", "Sold-Out Performance", "Record-Breaking Run", "Sold-Out Crowd Expected"),
)
_GAME_CUES: tuple[tuple[str, ...], ...] = (
    ("Community Night", "Youth Night", ""),
    ("", "", "Weeknight Game"),
    ("", "Live", "Game Night"),
    ("Rivalry Night", "Playoff Push", "Marquee Matchup"),
    ("Sold-Out", "Sold-Out Crowd Expected", "Standing Room Only"),
)
_FAIR_CUES: tuple[tuple[str, ...], ...] = (
    ("Community Day", "Free Admission", ""),
    ("", "", "Weekday Pass"),
    ("", "Live", "Now Open"),
    ("Expanded Show Floor", "Record Lineup", "By Popular Demand"),
    ("Sold-Out", "Sold-Out Passes", "Record Attendance Expected"),
)
#: Title cues by category and popularity tier; an empty string means no cue.
TITLE_CUES: dict[str, tuple[tuple[str, ...], ...]] = {
    "performing-arts": _SHOW_CUES,
    "concerts": _SHOW_CUES,
    "community": (
        ("Community Night", "Free Admission", ""),
        ("", "", "All Welcome"),
        ("", "Monthly Meetup", ""),
        ("Special Edition", "Annual Gathering"),
        ("Record Turnout Expected", "Sold-Out"),
    ),
    "sports": _GAME_CUES,
    "expos": _FAIR_CUES,
    "conferences": _FAIR_CUES,
    "festivals": _FAIR_CUES,
}
POPULARITY_PHRASES: tuple[tuple[str, ...], ...] = (
    ("A quiet evening with limited seating.", "A small gathering, free and open to neighbours.",
     "A low-key event; only a handful of people are expected.", "A modest turnout is expected."),
    ("Plenty of tickets are still available.", "A relaxed, uncrowded event.", "Tickets are easy to get."),
    ("A popular choice with good availability.", "Steady ticket sales so far.", "A solid crowd is expected."),
    ("Very popular: only a few tickets are left.", "Strong ticket sales and a near-capacity crowd expected.",
     "Demand has been high all week."),
    ("Highly anticipated and completely sold out.", "Tickets sold out weeks ago; expect huge crowds.",
     "One of the hottest tickets in town, with a packed house expected."),
)
CRITICS: tuple[tuple[str, ...], ...] = (
    ("Critics have been harsh.", "Early reviews are poor.", "Word of mouth has been negative."),
    ("Reviews have been mixed.", "Critics are divided.", "Audiences have given it middling marks."),
    ("Critics rave about it.", "Audiences love it.", "Reviews have been glowing."),
)

# ---------------------------------------------------------------- category words
LEADS: dict[str, tuple[str, ...]] = {
    "performing-arts": ("{t} takes the stage in a Broadway-style production with live orchestra and full cast.",
                        "{t}: a theatre performance with songs, dance and a celebrated cast.",
                        "See {t}, a stage production for theatre lovers, with curtain at the listed time."),
    "sports": ("{t}: live professional game action with fans filling the stands.",
               "Tip-off for {t}; catch the matchup live.", "{t} - a regular-season matchup with the home team."),
    "concerts": ("{t}: a live music concert with the full band on stage.",
                 "{t} brings its tour and a night of live music.", "Live concert: {t}, doors open an hour early."),
    "expos": ("{t}: a trade show with hundreds of exhibitors, booths and product demos.",
              "{t} fills the exhibition halls with exhibitors, vendors and demos.",
              "{t}, the industry expo: exhibitor booths, launches and buyers."),
    "conferences": ("{t}: keynote talks, breakout sessions and networking for professionals.",
                    "{t} brings speakers, panels and workshops for the industry.",
                    "{t}: a professional conference with keynotes and networking receptions."),
    "festivals": ("{t}: an outdoor festival with food vendors, music stages and activities.",
                  "{t} returns with live stages, food trucks and crafts.",
                  "{t}: a free outdoor celebration with music and food."),
    "community": ("{t}: a neighbourhood community event hosted by local volunteers.",
                  "{t} for local residents; all are welcome.", "{t}: a small community gathering in the neighbourhood."),
}
#: What reviewers talk about, per category (plural nouns end in "s" and take "were").
THINGS: dict[str, tuple[str, ...]] = {
    "performing-arts": ("cast", "songs", "staging", "costumes", "lead actress", "orchestra", "choreography", "second act"),
    "sports": ("game", "atmosphere", "fourth quarter", "home team", "seats", "defense", "crowd energy", "overtime"),
    "concerts": ("setlist", "sound", "band", "encore", "vocals", "light show", "opening act", "guitar solo"),
    "expos": ("exhibitors", "booths", "demos", "floor layout", "product launches", "vendor selection", "halls"),
    "conferences": ("speakers", "sessions", "keynote", "networking", "panels", "workshops", "catering"),
    "festivals": ("food", "music", "vendors", "stages", "lineup", "food trucks", "activities"),
    "community": ("organizers", "neighbours", "space", "discussion", "volunteers", "snacks", "turnout"),
}
POS_ADJ = ("amazing", "fantastic", "incredible", "wonderful", "superb", "outstanding", "brilliant", "electric",
           "unforgettable", "spectacular", "phenomenal", "excellent")
NEU_ADJ = ("decent", "okay", "alright", "average", "fine", "so-so", "standard", "reasonable", "fair")
NEG_ADJ = ("terrible", "awful", "disappointing", "boring", "mediocre", "underwhelming", "dull", "sloppy", "painful")
POS_TEMPLATES = ("{A} {x}!", "The {x} {be} {a}.", "Loved the {x}, {a} from start to finish.",
                 "Would absolutely come back, the {x} {be} {a}.", "Best night out in ages, {a} {x}.",
                 "Highly recommend it. The {x} {be} {a}.")
NEU_TEMPLATES = ("The {x} {be} {a}.", "It was okay, the {x} {be} {a}.", "Decent {x}, nothing special.",
                 "Average experience overall; the {x} {be} {a}.", "Not bad, not great. {A} {x}.")
NEG_TEMPLATES = ("The {x} {be} {a}.", "Disappointing {x}, would not recommend.", "Waste of money, the {x} {be} {a}.",
                 "Overpriced and the {x} {be} {a}.", "Left early. {A} {x}.", "Really {a} {x}, skip it.")
BIG_CROWD = ("Huge crowds outside afterwards.", "The line to get in went around the block.",
             "Traffic around the venue was a nightmare.", "Impossible to get a cab after it ended.",
             "Packed house, every seat taken.", "Streets were jammed before it started.",
             "Took forever to get out with the crowds.", "Sold out and absolutely packed.")
SMALL_CROWD = ("Only a handful of people there.", "Half-empty room.", "Easy to find a seat.",
               "Quiet and relaxed crowd.", "Small turnout, very low-key.")
#: What reviewers of a venue talk about, and how they speak of its size.
VENUE_THINGS = ("seats", "sightlines", "staff", "bathrooms", "location", "security line", "bar", "acoustics")
VENUE_BIG = ("A huge place; getting in and out takes a while.", "Massive venue, plan extra time to leave.",
             "Thousands of people, lines everywhere.")
VENUE_SMALL = ("Cozy little room.", "Tiny venue, very intimate.", "Small space, you are close to the stage.")


def venue_reviews(rng: random.Random, venue_name: str, kind: str, capacity: int) -> tuple[str, ...]:
    """Three to eight reviews of the venue itself: its facilities, and its size."""
    out = []
    for _ in range(rng.randint(3, 8)):
        kind_of = rng.choices((0, 1, 2), weights=(0.5, 0.3, 0.2))[0]
        templates, adjs = ((POS_TEMPLATES, POS_ADJ), (NEU_TEMPLATES, NEU_ADJ), (NEG_TEMPLATES, NEG_ADJ))[kind_of]
        a, x = rng.choice(adjs), rng.choice(VENUE_THINGS)
        be = "were" if x.endswith("s") else "was"
        text = f"{venue_name}: " + rng.choice(templates).format(x=x, be=be, a=a, A=a.capitalize())
        if capacity >= 5000 and rng.random() < 0.5:
            text += " " + rng.choice(VENUE_BIG)
        elif capacity < 500 and rng.random() < 0.5:
            text += " " + rng.choice(VENUE_SMALL)
        out.append(text)
    return tuple(out)


def popularity_tier(popularity: float) -> int:
    """The tier (0 … 4) of a popularity in [0, 1]."""
    return sum(popularity >= b for b in TIER_BOUNDS)


def concert_name(rng: random.Random) -> str:
    return f"The {rng.choice(BAND_ADJ)} {rng.choice(BAND_NOUN)}: {rng.choice(TOUR_SUFFIX)}"


def conference_name(rng: random.Random, year: int) -> str:
    return f"{rng.choice(CONF_TOPICS)} {rng.choice(CONF_FORMATS)} {year}"


def title(rng: random.Random, category: str, name: str, popularity: float, cue: str | None = None) -> str:
    """Event title: the name plus a popularity cue (a given ``cue`` such as ``Opening Night`` wins)."""
    if cue is None:
        cue = rng.choice(TITLE_CUES[category][popularity_tier(popularity)])
    return f"{name} - {cue}" if cue else name


def venue_phrase(venue_name: str, kind: str, capacity: int, unit: str = "seat") -> str:
    """Where, and how big: seat counts let text alone tell a club from an arena."""
    size = "an intimate" if capacity < 500 else "a large" if capacity >= 5000 else "a"
    return f"At {venue_name}, {size} {capacity:,}-{unit} {kind}."


def description(
    rng: random.Random,
    category: str,
    event_title: str,
    venue: str,
    popularity: float,
    sentiment: float,
    start: dt.datetime,
) -> str:
    """Description: category lead, venue and size, popularity phrase, critics' sentence, start time.

    ``venue`` is a :func:`venue_phrase`.
    """
    lead = rng.choice(LEADS[category]).format(t=event_title)
    pop = rng.choice(POPULARITY_PHRASES[popularity_tier(popularity)])
    critics = rng.choice(CRITICS[0 if sentiment < 0.4 else 1 if sentiment < 0.7 else 2])
    when = f"{start:%A %B} {start.day} at {start.hour % 12 or 12}:{start.minute:02d} {'PM' if start.hour >= 12 else 'AM'}"
    return f"{lead} {venue} {pop} {critics} Starts {when}."


def review_count(rng: random.Random, popularity: float) -> int:
    """Number of reviews: 1 … 100, roughly ``100 · popularity^1.5``."""
    n = round(MAX_REVIEWS * popularity**1.5 * rng.uniform(0.85, 1.15)) + 1
    return max(1, min(MAX_REVIEWS, n))


def reviews(
    rng: random.Random,
    category: str,
    reputation: float,
    sentiment: float,
    crowd: float,
) -> tuple[str, ...]:
    """Up to 100 short reviews of a performer's earlier events: count, tone and crowd remarks.

    ``reputation`` is the performer's standing before this event and
    ``crowd`` the crowd its earlier events drew at a venue like this one
    (never this event's attendance).  The share of positive reviews grows
    with ``sentiment`` and the share of negative ones shrinks; crowds of
    several thousand draw crowd, line and traffic remarks, small ones
    remarks on a thin turnout.
    """
    n = review_count(rng, reputation)
    p_pos = 0.05 + 0.85 * sentiment**1.2
    p_neg = 0.05 + 0.6 * (1.0 - sentiment) ** 1.5
    p_neu = max(0.05, 1.0 - p_pos - p_neg)
    kinds = rng.choices((0, 1, 2), weights=(p_pos, p_neu, p_neg), k=n)
    crowd_p = min(0.6, crowd / 15000.0) if crowd >= 1500 else 0.0
    small_p = 0.4 if crowd < 250 else 0.0
    things = THINGS[category]
    out = []
    for kind in kinds:
        templates, adjs = ((POS_TEMPLATES, POS_ADJ), (NEU_TEMPLATES, NEU_ADJ), (NEG_TEMPLATES, NEG_ADJ))[kind]
        a = rng.choice(adjs)
        x = rng.choice(things)
        be = "were" if x.endswith("s") and x != "sound" else "was"
        text = rng.choice(templates).format(x=x, be=be, a=a, A=a.capitalize())
        u = rng.random()
        if u < crowd_p:
            text += " " + rng.choice(BIG_CROWD)
        elif u < small_p:
            text += " " + rng.choice(SMALL_CROWD)
        out.append(text)
    return tuple(out)
