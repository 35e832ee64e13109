import workbench as wb
rec = wb.datasets.load("seed_individual_deck")   # embedded records by name; wb.load_record(path, mass_kg=...)
model = wb.SMDModel(harmonics=6)                  # add effects with +, e.g. + wb.effects.GaitAsymmetry()
res = wb.identify(rec, model, seed=1)             # exact posterior; or method=wb.RBPF(...)
print(res.summary()); res.params; res.conf_int(); res.plot_diagnostics()
rigid = wb.identify(wb.datasets.load("treadmill").slice(40, 70), model, seed=1)
print(rigid.summary())
d = wb.diagnose(rec, model); print(d.summary())
