"""The fabric presets (``material.preset``), with no imports: the settings' schema
(cloth/settings.py) and the model's ``Material`` defaults (cloth/model.py) both read them
from here."""

# Fabric presets in lab units (SI): areal density kg/m^2; stretch and shear stiffnesses are
# membrane moduli per unit width (N/m, as a KES-FB1 tensile/shear test or a strip test gives
# them); k_bend is the flexural rigidity B (N m, per unit width, as a KES-FB2 bending test or
# an ASTM D1388 cantilever gives it: B = w c^3, w = density * g, c the bending length);
# k_bend_warp / k_bend_weft are B along the warp and the weft (0 = k_bend): the measured fabrics
# of fabrics/*.toml set them (cloth/fabrics.py), these presets are isotropic.
# benchmarks/calibration.py checks that the simulated cloth has these values
# (docs/calibration/calibration.md).
MATERIAL_PRESETS = {
    # The paper's stretchy test cloth, soft on purpose: under its own weight it stretches well
    # past 5 % near the pins, so the paper's 1 % / 5 % strain limits bind, as in its experiment
    # (Table 1); not a real fabric. Its bending is the one it always had (k_bend was 2e-6 with
    # the discrete-shells weight 3 |e|^2 / (A1 + A2); 2e-6 x 3 / 1.17, the calibrated weight,
    # keeps every edge's stiffness), now stated as what it is: B = 5.13e-6 N m, bending
    # length (B / w)^(1/3) = 1.52 cm, a light shirting's.
    "soft": dict(density=0.15, k_warp=20.0, k_weft=20.0, k_shear=4.0, k_bend=5.13e-6,
                 k_bend_warp=0.0, k_bend_weft=0.0, damp_mass=0.2, damp_stiff=0.002),
    # Woven cotton shirting, about 150 g/m^2. Tensile moduli: woven cotton's initial modulus is
    # roughly 2-8 kN/m per unit width, warp stiffer than weft. Shear: 50 N/m (per radian) is
    # 0.9 gf/cm/deg, inside KES-FB1's usual 0.5-2 gf/cm/deg for cotton wovens. Bending: KES-FB2
    # bending rigidities of cotton shirtings are around 0.05-0.2 gf cm^2/cm (1 gf cm^2/cm =
    # 9.81e-5 N m), i.e. 5-20 uN m; B = 1.5e-5 N m (0.15 gf cm^2/cm) gives a bending length of
    # 2.2 cm, a typical cantilever reading for a shirting. Isotropic bending (one B for warp
    # and weft; see the README).
    "cotton": dict(density=0.15, k_warp=3000.0, k_weft=2000.0, k_shear=50.0, k_bend=1.5e-5,
                   k_bend_warp=0.0, k_bend_weft=0.0, damp_mass=0.1, damp_stiff=0.002),
}
