"""Real-format readers: trips, weather, points of interest, occupancy and events."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from city.errors import DataError
from city.graph import City
from city.io.events import MAX_REVIEWS, read_events, read_permitted_events, read_reviews
from city.io.occupancy import HOUR_COLUMNS, SCHEDULES, read_occupancy_csv
from city.io.poi import read_poi_csv
from city.io.trips import hourly_counts, od_matrix, read_fhvhv, read_yellow_csv
from city.io.weather import read_weather_csv

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data not available")


@pytest.fixture(scope="module")
def toy() -> City:
    """A 4x4 lon/lat grid near Times Square: west half TLC zone 161, east half zone 230."""
    lon, lat = np.meshgrid(-73.990 + 0.001 * np.arange(4), 40.755 + 0.001 * np.arange(4))
    xy = np.column_stack([lon.ravel(), lat.ravel()])
    u, v = [], []
    for i in range(16):
        r, c = divmod(i, 4)
        for j in ([i + 1] if c < 3 else []) + ([i + 4] if r < 3 else []):
            u += [i, j]
            v += [j, i]
    sector = (np.arange(16) % 4 >= 2).astype(int)
    return City.build("toy", xy, np.array(u), np.array(v), np.full(len(u), 100.0), sector, ["Midtown Center", "Times Sq/Theatre District"],
                      crs="lonlat", sector_ids=np.array([161, 230]))


# ------------------------------------------------------------------ trips
FHVHV_SCHEMA = pa.schema(
    [("hvfhs_license_num", pa.string()), ("dispatching_base_num", pa.string()), ("originating_base_num", pa.string()),
     ("request_datetime", pa.timestamp("us")), ("on_scene_datetime", pa.timestamp("us")), ("pickup_datetime", pa.timestamp("us")),
     ("dropoff_datetime", pa.timestamp("us")), ("PULocationID", pa.int64()), ("DOLocationID", pa.int64()), ("trip_miles", pa.float64()),
     ("trip_time", pa.int64())]
    + [(c, pa.float64()) for c in ("base_passenger_fare", "tolls", "bcf", "sales_tax", "congestion_surcharge", "airport_fee", "tips", "driver_pay")]
    + [(c, pa.string()) for c in ("shared_request_flag", "shared_match_flag", "access_a_ride_flag", "wav_request_flag", "wav_match_flag")]
)


def write_fhvhv(path: Path, rows: list[tuple], drop: str | None = None) -> Path:
    """Rows of (request, pickup, PU, DO) in the official schema, other columns filled plausibly."""
    n = len(rows)
    data = {f.name: pa.nulls(n, f.type) for f in FHVHV_SCHEMA}
    data["hvfhs_license_num"] = pa.array(["HV0003"] * n)
    data["request_datetime"] = pa.array([r[0] for r in rows], pa.timestamp("us"))
    data["pickup_datetime"] = pa.array([r[1] for r in rows], pa.timestamp("us"))
    data["PULocationID"] = pa.array([r[2] for r in rows], pa.int64())
    data["DOLocationID"] = pa.array([r[3] for r in rows], pa.int64())
    table = pa.table(data, schema=FHVHV_SCHEMA)
    if drop:
        table = table.drop_columns([drop])
    pq.write_table(table, path)
    return path


def test_fhvhv_parquet(tmp_path, toy):
    t = dt.datetime
    rows = [
        (t(2022, 1, 1, 0, 5, 30), t(2022, 1, 1, 0, 9), 161, 230),
        (None, t(2022, 1, 1, 1, 2), 230, 230),  # no request time: pickup time used
        (t(2022, 3, 1, 8, 0), t(2022, 3, 1, 8, 7), 161, 132),  # to JFK: outside the city
        (t(2022, 3, 1, 8, 1), t(2022, 3, 1, 8, 9), None, 161),
    ]
    trips = read_fhvhv([write_fhvhv(tmp_path / "a.parquet", rows[:2]), write_fhvhv(tmp_path / "b.parquet", rows[2:])], toy)
    assert (trips.n_read, trips.n_dropped, len(trips)) == (4, 2, 2)
    assert list(trips.request_time) == [np.datetime64("2022-01-01T00:05"), np.datetime64("2022-01-01T01:02")]
    assert list(trips.pickup_sector) == [0, 1] and list(trips.dropoff_sector) == [1, 1]
    counts = hourly_counts(trips, 2022, toy.n_sectors)
    assert counts.shape == (8760, 2) and counts[0, 0] == 1 and counts[1, 1] == 1 and counts.sum() == 2
    beta = od_matrix(trips, toy.n_sectors)
    np.testing.assert_allclose(beta, [[0, 1], [0, 1]])
    empty = od_matrix(read_fhvhv(tmp_path / "b.parquet", toy), toy.n_sectors)
    np.testing.assert_allclose(empty, 0.5)  # no data: uniform rows


def test_fhvhv_missing_column(tmp_path, toy):
    path = write_fhvhv(tmp_path / "fhvhv_tripdata_2022-01.parquet", [(None, dt.datetime(2022, 1, 1), 161, 230)], drop="PULocationID")
    with pytest.raises(DataError, match=r"fhvhv_tripdata_2022-01\.parquet: missing column 'PULocationID'"):
        read_fhvhv(path, toy)


def test_fhvhv_not_parquet(tmp_path, toy):
    path = tmp_path / "x.parquet"
    path.write_text("not parquet")
    with pytest.raises(DataError, match=r"x\.parquet: not a readable parquet file"):
        read_fhvhv(path, toy)


YELLOW = "id,vendor_id,pickup_datetime,dropoff_datetime,passenger_count,pickup_longitude,pickup_latitude,dropoff_longitude,dropoff_latitude,store_and_fwd_flag,trip_duration\n"


def test_yellow_csv(tmp_path, toy):
    path = tmp_path / "yellow.csv"
    path.write_text(YELLOW + "a,1,2016-01-08 22:31:12,2016-01-08 22:39:57,1,-73.9899,40.7551,-73.9871,40.7579,N,525\n"
                             "b,1,2016-01-08 22:31:12,2016-01-08 22:39:57,1,-73.9899,40.7551,-73.7800,40.6400,N,525\n")
    trips = read_yellow_csv(path, toy)
    assert (len(trips), trips.n_dropped) == (1, 1)
    assert (trips.pickup_sector[0], trips.dropoff_sector[0]) == (0, 1)
    path.write_text(YELLOW + "a,1,08/01/2016,x,1,-73.99,40.75,-73.98,40.75,N,525\n")
    with pytest.raises(DataError, match=r"yellow\.csv, row 2: column 'pickup_datetime': '08/01/2016' is not a date"):
        read_yellow_csv(path, toy)


# ---------------------------------------------------------------- weather
AIRPORT_HEADER = "origin,year,month,day,hour,temp,dewp,humid,wind_dir,wind_speed,wind_gust,precip,pressure,visib,time_utc,time_local_ny\n"


def airport_row(origin: str, local: str, temp: float | str, wind: float | str = 5.0, precip: float = 0.0) -> str:
    return f"{origin},2022,1,1,0,{temp},40,80,160,{wind},,{precip},1014,10,x,{local}\n"


def test_weather_airport_schema(tmp_path):
    rows = [airport_row("LGA", "2021-12-31 23:00:00-05:00", 99.0), airport_row("EWR", "2022-01-01 00:00:00-05:00", 0.0)]
    rows += [airport_row("LGA", "2022-01-01 00:00:00-05:00", 40.0), airport_row("LGA", "2022-01-01 04:00:00-05:00", 44.0, wind="")]
    rows += [airport_row("LGA", "2022-03-13 01:00:00-05:00", 30.0, precip=0.1), airport_row("LGA", "2022-03-13 03:00:00-04:00", 34.0)]
    rows += [airport_row("LGA", "2022-11-06 01:00:00-04:00", 50.0), airport_row("LGA", "2022-11-06 01:00:00-05:00", 52.0)]
    path = tmp_path / "airports.csv"
    path.write_text(AIRPORT_HEADER + "".join(rows))
    with pytest.warns(UserWarning, match="interpolated"):
        w = read_weather_csv(path, station="LGA", year=2022)
    assert w.temp_f.shape == (8760,) and "LGA" in w.source
    np.testing.assert_allclose(w.temp_f[:5], [40, 41, 42, 43, 44])  # gap interpolated; EWR and 2021 ignored
    spring = w.index(dt.datetime(2022, 3, 13, 2))
    assert w.temp_f[spring] == 30.0 and w.precip_in[spring] == 0.1  # skipped hour = previous hour
    assert w.temp_f[w.index(dt.datetime(2022, 11, 6, 1))] == 51.0  # repeated hour averaged
    assert w.temp_f[-1] == 51.0 and w.wind_mph[4] == 5.0


def test_weather_errors(tmp_path):
    path = tmp_path / "w.csv"
    path.write_text(AIRPORT_HEADER + airport_row("LGA", "2022-01-01 00:00:00-05:00", 40) + airport_row("LGA", "2022-01-01 01:00:00-05:00", "warm"))
    with pytest.raises(DataError, match=r"w\.csv, row 3: column 'temp': 'warm' is not a number"):
        read_weather_csv(path)
    with pytest.raises(DataError, match=r"w\.csv: no rows for station 'JFK' \(stations: LGA\)"):
        read_weather_csv(path, station="JFK")
    path.write_text("time,temp_f,precip_in,wind_mph\n2022-01-01 00:00,40,0,3\n2022-13-01 01:00,41,0,3\n")
    with pytest.raises(DataError, match=r"w\.csv, row 3: column 'time': '2022-13-01 01:00' is not a date"):
        read_weather_csv(path)
    path.write_text("time,temp_f,wind_mph\n")
    with pytest.raises(DataError, match=r"w\.csv, row 1: missing column\(s\) 'precip_in'"):
        read_weather_csv(path)


def test_weather_generic_schema(tmp_path):
    path = tmp_path / "w.csv"
    hours = [dt.datetime(2021, 1, 1) + dt.timedelta(hours=h) for h in range(8760)]
    path.write_text("time,temp_f,precip_in,wind_mph\n" + "".join(f"{t:%Y-%m-%dT%H:%M},{h % 50},0,{h % 7}\n" for h, t in enumerate(hours)))
    w = read_weather_csv(path, year=2021)
    np.testing.assert_allclose(w.temp_f, np.arange(8760) % 50)


@needs_shared
def test_weather_real_file():
    with pytest.warns(UserWarning, match="interpolated"):
        w = read_weather_csv(SHARED / "nyc" / "weather" / "airports_hourly_2022.csv", station="LGA", year=2022)
    assert len(w.temp_f) == 8760 and np.isfinite(w.temp_f).all()
    assert 30 < w.temp_f[w.index(dt.datetime(2022, 1, 15, 12))] < 60 or w.temp_f.min() < 20
    assert w.temp_f[w.index(dt.datetime(2022, 7, 20, 15))] > 80


# -------------------------------------------------------------------- POIs
POI_HEADER = "the_geom,COMPLEXID,SAFTYPE,SEGMENTID,SOS,PLACEID,FACI_DOM,BIN,BOROUGH,CREATED,MODIFIED,FACILITY_T,SOURCE,B7SC,PRI_ADD,NAME\n"


def poi_row(wkt: str, facility: int, domain: int, name: str, borough: int = 1) -> str:
    return f'"{wkt}",0,N,1,1,1,{domain},0,{borough},x,x,{facility},DCP,1,0,{name}\n'


def test_poi_nyc_schema(tmp_path):
    path = tmp_path / "poi.csv"
    path.write_text(POI_HEADER + "".join([
        poi_row("POINT (-73.98 40.75)", 7, 4, "ALGONQUIN HOTEL"),
        poi_row("POINT (-73.98 40.75)", 7, 2, "PARK SUITES"),
        poi_row("POINT (-73.98 40.75)", 7, 5, "21 CLUB"),
        poi_row("POINT (-73.98 40.75)", 7, 1, "HUDSON YARDS SHOPS"),
        poi_row("POINT (-73.98 40.75)", 10, 4, "BELLEVUE HOSPITAL CENTER"),
        poi_row("POINT (-73.98 40.75)", 10, 3, "UNION CLINIC"),
        poi_row("POINT (-73.97 40.76)", 3, 1, "MUSEUM"),
        poi_row("POINT (-73.8 40.7)", 7, 4, "QUEENS HOTEL", borough=4),
    ]))
    pois = read_poi_csv(path)
    assert list(pois.kind) == ["hotel", "hotel", "restaurant", "retail", "hospital", "other", "other"]
    assert pois.x[-1] == -73.97 and pois.y[-1] == 40.76
    assert len(read_poi_csv(path, borough=None).x) == 8


def test_poi_bad_wkt(tmp_path):
    path = tmp_path / "poi.csv"
    path.write_text(POI_HEADER + poi_row("POINT (-73.98 40.75)", 7, 4, "A") + poi_row("POINT (-73.98, 40.75)", 7, 4, "B"))
    with pytest.raises(DataError, match=r"poi\.csv, row 3: column 'the_geom': 'POINT \(-73\.98, 40\.75\)' is not a WKT POINT"):
        read_poi_csv(path)


def test_poi_generic_schema(tmp_path):
    path = tmp_path / "poi.csv"
    path.write_text("lon,lat,kind,name\n-73.98,40.75,hotel,H\n-73.97,40.76,restaurant,\n")
    pois = read_poi_csv(path)
    assert list(pois.kind) == ["hotel", "restaurant"] and list(pois.name) == ["H", ""]
    path.write_text("x,y,kind\n10,20,retail\n30,40,bar\n")
    with pytest.raises(DataError, match=r"poi\.csv, row 3: column 'kind': 'bar' is not one of"):
        read_poi_csv(path)


@needs_shared
def test_poi_real_file():
    pois = read_poi_csv(SHARED / "nyc" / "poi" / "nyc_points_of_interest.csv")
    kinds = dict(zip(*np.unique(pois.kind, return_counts=True)))
    assert len(pois.x) == 5800 and kinds["hotel"] > 200 and kinds["hospital"] > 30 and kinds["retail"] > 50
    assert (pois.x > -74.05).all() and (pois.x < -73.9).all()


# -------------------------------------------------------------- occupancy
def occupancy_table(drop_hour_in: str | None = None) -> str:
    lines = ["schedule,day_type," + ",".join(HOUR_COLUMNS)]
    names = {"retail": "Retail Bldg Occ", "restaurant": "restaurant", "hotel": "LargeHotel Bldg Occ", "hospital": "Hospital Bldg Occ"}
    for loc, name in names.items():
        for day, values in SCHEDULES[loc].items():
            cells = [str(v) for v in values]
            if name == drop_hour_in and day == "saturday":
                cells = cells[:-1]
            lines.append(f"{name},{day}," + ",".join(cells))
    lines.append("Office Bldg Occ,weekday," + ",".join(["2.0"] * 24))  # ignored
    return "\n".join(lines) + "\n"


def test_occupancy_csv(tmp_path):
    path = tmp_path / "occ.csv"
    path.write_text(occupancy_table())
    schedules = read_occupancy_csv(path)
    assert schedules == {loc: {d: tuple(map(float, v)) for d, v in days.items()} for loc, days in SCHEDULES.items()}


def test_occupancy_wrong_hour_count(tmp_path):
    path = tmp_path / "occ.csv"
    path.write_text(occupancy_table(drop_hour_in="LargeHotel Bldg Occ"))
    with pytest.raises(DataError, match=r"occ\.csv, row 9: expected 24 hourly values h00\.\.h23, found 23"):
        read_occupancy_csv(path)


def test_occupancy_bad_value_and_missing_day(tmp_path):
    path = tmp_path / "occ.csv"
    path.write_text(occupancy_table().replace("Retail Bldg Occ,weekday,0,", "Retail Bldg Occ,weekday,1.5,"))
    with pytest.raises(DataError, match=r"occ\.csv, row 2: column 'h00': '1\.5' is not a fraction in \[0, 1\]"):
        read_occupancy_csv(path)
    path.write_text("\n".join(line for line in occupancy_table().splitlines() if not line.startswith("restaurant,sunday")) + "\n")
    with pytest.raises(DataError, match=r"occ\.csv: schedule 'restaurant' lacks day type\(s\) sunday"):
        read_occupancy_csv(path)


@needs_shared
def test_occupancy_real_file():
    schedules = read_occupancy_csv(SHARED / "occupancy" / "reference_building_occupancy_hourly.csv")
    assert schedules["hotel"]["weekday"] == tuple(map(float, SCHEDULES["hotel"]["weekday"]))


# ----------------------------------------------------------------- events
EVENTS_CSV = (
    "event_id,title,description,category,start,end,lat,lon,venue,attendance\n"
    'e1,Jazz night,"A long\nevening of jazz",concerts,2022-03-01 19:00,2022-03-01 22:00,40.7551,-73.9899,Hall A,1200\n'
    "e2,Tech expo,Gadgets,expos,2022-03-02T14:00:00Z,2022-03-02T22:00:00Z,40.7579,-73.9871,,\n"
    "e3,Far away,Elsewhere,sports,2022-03-03 12:00,2022-03-03 15:00,40.6400,-73.7800,JFK,\n"
)


def test_events_csv_with_reviews(tmp_path, toy):
    events_path, reviews_path = tmp_path / "events.csv", tmp_path / "reviews.csv"
    events_path.write_text(EVENTS_CSV)
    reviews_path.write_text("event_id,review\ne1,Great sound\ne1,\ne2,Crowded\n" + "".join(f"e2,review {k}\n" for k in range(150)))
    reviews = read_reviews(reviews_path)
    assert reviews["e1"] == ["Great sound"] and len(reviews["e2"]) == MAX_REVIEWS
    with pytest.warns(UserWarning, match=r"dropped 1 of 3 events"):
        events = read_events(events_path, toy, reviews=reviews_path)
    e1, e2 = events
    assert e1.description == "A long\nevening of jazz" and e1.attendance == 1200.0 and e1.venue_id == "Hall A"
    assert (e1.sector, e2.sector) == (0, 1) and e1.reviews == ("Great sound",)
    assert e2.start == dt.datetime(2022, 3, 2, 9, 0) and e2.attendance is None  # 14:00 UTC = 09:00 EST
    assert e2.reviews[0] == "Crowded" and len(e2.reviews) == MAX_REVIEWS


def test_events_csv_errors(tmp_path, toy):
    path = tmp_path / "events.csv"
    path.write_text(EVENTS_CSV.replace("expos", "public-holidays"))
    with pytest.warns(UserWarning, match=r"events\.csv: skipped 1 of 3 events whose category .*\(public-holidays; first at row 4\)"):
        events = read_events(path, toy)  # row 4: e1's description spans lines 2-3
    assert [e.event_id for e in events] == ["e1"]
    path.write_text(EVENTS_CSV.replace("2022-03-02T14:00:00Z", "March 2nd"))
    with pytest.raises(DataError, match=r"events\.csv, row 4: field 'start': 'March 2nd' is not an ISO 8601"):
        read_events(path, toy)
    path.write_text(EVENTS_CSV.replace("2022-03-01 22:00", "2022-02-01 22:00"))
    with pytest.raises(DataError, match=r"events\.csv, row 2: field 'end'.*before start"):
        read_events(path, toy)


def test_events_json_predicthq(tmp_path, toy):
    page = {"count": 2, "results": [
        {"id": "p1", "title": "Marathon expo", "description": "Bib pickup", "category": "expos", "start": "2022-11-04T14:00:00Z",
         "end": "2022-11-04T22:00:00Z", "timezone": "America/New_York", "location": [-73.9899, 40.7551], "phq_attendance": 5000,
         "entities": [{"name": "Javits", "type": "venue"}], "reviews": ["Busy", " "]},
        {"event_id": "p2", "title": "Show", "category": "performing-arts", "start": "2022-11-05 20:00", "end": "2022-11-05 23:00",
         "lat": 40.7579, "lon": -73.9871},
    ]}
    path = tmp_path / "events.json"
    path.write_text(json.dumps(page, indent=2))
    p1, p2 = read_events(path, toy)
    assert p1.start == dt.datetime(2022, 11, 4, 10, 0) and p1.venue_id == "Javits" and p1.attendance == 5000.0
    assert p1.reviews == ("Busy",) and p1.sector == 0 and p2.sector == 1 and p2.description == ""


def test_events_json_errors(tmp_path, toy):
    items = [
        {"id": "a", "title": "A", "category": "concerts", "start": "2022-01-01 20:00", "end": "2022-01-01 22:00", "location": [-73.99, 40.755]},
        {"id": "b", "title": "B", "category": "raves", "start": "2022-01-01 20:00", "end": "2022-01-01 22:00", "location": [-73.99, 40.755]},
    ]
    path = tmp_path / "events.json"
    path.write_text(json.dumps(items, indent=1))
    with pytest.warns(UserWarning, match=r"events\.json: skipped 1 of 2 events .*\(raves; first at row 13\)"):
        assert [e.event_id for e in read_events(path, toy)] == ["a"]
    items[1]["category"], items[1]["start"] = "concerts", "2022-01-01 25:00"
    path.write_text(json.dumps(items, indent=1))
    with pytest.raises(DataError, match=r"events\.json, row 13: field 'start': '2022-01-01 25:00'"):
        read_events(path, toy)
    path.write_text('[{"id": "a",\n "title": }]')
    with pytest.raises(DataError, match=r"events\.json, row 2: not valid JSON"):
        read_events(path, toy)


def test_permitted_events(tmp_path, toy):
    path = tmp_path / "permits.csv"
    header = "Event ID,Event Name,Start Date/Time,End Date/Time,Event Agency,Event Type,Event Borough,Event Location,Event Street Side,Street Closure Type,Community Board,Police Precinct\n"
    path.write_text(header
                    + '1,Plaza show,03/01/2022 07:00:00 PM,03/01/2022 09:00:00 PM,Parks,Special Event,Manhattan,"43/44 Broadway Pedestrian Plaza (Times Square): x",,N/A,"5,","14,"\n'
                    + '2,Soccer,03/02/2022 09:00:00 AM,03/02/2022 11:00:00 AM,Parks,Sport - Youth,Manhattan,Central Park: Great Lawn,,N/A,"64,","22,"\n'
                    + '3,Fair,03/02/2022 09:00:00 AM,03/02/2022 11:00:00 AM,Parks,Special Event,Brooklyn,Times Square,,N/A,"1,","1,"\n')
    with pytest.warns(UserWarning, match=r"1 of 2 Manhattan events have no location"):
        (event,) = read_permitted_events(path, toy)
    assert event.sector == 1 and event.start == dt.datetime(2022, 3, 1, 19) and event.category == "community"
    assert event.description == "" and event.reviews == ()
    path.write_text(header + '1,Show,2022-03-01 19:00,03/01/2022 09:00:00 PM,Parks,Special Event,Manhattan,Times Square,,N/A,"5,","14,"\n')
    with pytest.raises(DataError, match=r"permits\.csv, row 2: column 'Start Date/Time': '2022-03-01 19:00' is not a date/time \(%m/%d/%Y"):
        read_permitted_events(path, toy)
