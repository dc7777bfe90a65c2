"""Session 20: the ablation's rows with the paper-width predictor, paired per hour, beside the same pairs
with the reduced predictor (the full protocol's committed ablation). Run from the repository root:
python benchmarks/s20-paper-width-ablation-pairs.py"""
import json

from coordinator.evaluate import read_results
from pairs import FULL, compare, rows

M = "model=runs/pred-paper-s18"
P = f"surge:{M}"
OLD = "surge, paper-width (session 18's weights)"
path = "benchmarks/s20-paper-width-ablation.json"
pairs = ((f"surge:base=ia,{M}", P), (f"surge:scope=map,{M}", P), (f"surge:prune=none,samples=100,{M}", f"surge:samples=100,{M}"), (P, OLD))
doc = read_results(path)
out = compare(path, doc, rows("benchmarks/s19-paper-width-routing-main.json"), {P: OLD}, pairs)
# The same pairs with the reduced predictor, on the same instances.
ablation = FULL + "results-ablation.json"
abl = read_results(ablation)
out += compare(ablation, abl, rows(abl), {},
               (("surge:base=ia", "surge"), ("surge:scope=map", "surge"), ("surge:prune=none,samples=100", "surge:samples=100")))
# garces2023's certainty-equivalence rows with the paper-width model; its plain row is session 19's (session 18's weights).
G, LIM, CNT = "garces2023:forecast=model", "garces2023:forecast=model,ce=limited", "garces2023:forecast=model,ce=counts"
ce = "benchmarks/s20-paper-width-ce.json"
borrowed = rows(doc) | rows("benchmarks/s19-paper-width-garces-model.json")
out += compare(ce, read_results(ce), borrowed, {P: P, f"{G},{M}": f"{G}, paper-width (session 18's weights)"},
               ((f"{CNT},{M}", f"{G}, paper-width (session 18's weights)"), (f"{LIM},{M}", f"{CNT},{M}"), (P, f"{LIM},{M}")))
out += compare(ablation, abl, rows(abl), {}, ((CNT, G), (LIM, CNT), ("surge", LIM)))
json.dump(out, open("benchmarks/s20-paper-width-ablation-pairs.json", "w"), indent=1)
