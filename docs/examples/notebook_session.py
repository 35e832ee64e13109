import workbench as wb
rec = wb.datasets.load("treadmill")          # embedded records by name; wb.load_record(path, mass_kg=...)
model = wb.SMDModel(harmonics=6) + wb.effects.GaitAsymmetry()
res = wb.identify(rec.slice(10, 40), model, method="rbpf", seed=1)   # or method=wb.RBPF(...)
print(res.summary()); res.params; res.conf_int(); res.plot_diagnostics()
d = wb.diagnose(rec.slice(10, 70), model); print(d.summary())
