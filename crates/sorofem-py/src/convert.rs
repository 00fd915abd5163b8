//! Every numpy conversion and shape check of the bindings, in one place. Messages name the
//! parameter, the expected shape and dtype, and what was given.

use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyDictMethods};
use sorofem_core::material::{MaterialModel, Volumetric};
use sorofem_core::Loads;
use sorofem_core::{Error, Orientation, PressureMass};

/// An `(n, 3)` float64 array as node-major triples.
pub fn points(param: &str, array: &Bound<'_, PyAny>) -> Result<Vec<[f64; 3]>, Error> {
    let array: PyReadonlyArray2<f64> = array
        .extract()
        .map_err(|_| Error::shape(param, "a float64 array of shape (n, 3)", describe(array)))?;
    let shape = array.shape();
    if shape[1] != 3 {
        return Err(Error::shape(
            param,
            "shape (n, 3)",
            format!("shape ({}, {})", shape[0], shape[1]),
        ));
    }
    let view = array.as_array();
    Ok(view
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2]])
        .collect())
}

/// An `(m, 4)` integer array.
pub fn tets(param: &str, array: &Bound<'_, PyAny>) -> Result<Vec<[i64; 4]>, Error> {
    let array: PyReadonlyArray2<i64> = array
        .extract()
        .map_err(|_| Error::shape(param, "an int64 array of shape (m, 4)", describe(array)))?;
    let shape = array.shape();
    if shape[1] != 4 {
        return Err(Error::shape(
            param,
            "shape (m, 4)",
            format!("shape ({}, {})", shape[0], shape[1]),
        ));
    }
    Ok(array
        .as_array()
        .rows()
        .into_iter()
        .map(|r| [r[0], r[1], r[2], r[3]])
        .collect())
}

/// A 1-d float64 array of length `len` (any length when `None`).
pub fn vector(
    param: &str,
    array: &Bound<'_, PyAny>,
    len: Option<usize>,
) -> Result<Vec<f64>, Error> {
    let array: PyReadonlyArray1<f64> = array
        .extract()
        .map_err(|_| Error::shape(param, "a 1-d float64 array", describe(array)))?;
    let values = array.as_array().to_vec();
    if let Some(len) = len {
        if values.len() != len {
            return Err(Error::shape(
                param,
                &format!("shape ({len},)"),
                format!("shape ({},)", values.len()),
            ));
        }
    }
    Ok(values)
}

/// A 2-d float64 array as rows, with `cols` columns when given (any number of rows).
pub fn matrix(
    param: &str,
    array: &Bound<'_, PyAny>,
    cols: Option<usize>,
) -> Result<Vec<Vec<f64>>, Error> {
    let array: PyReadonlyArray2<f64> = array
        .extract()
        .map_err(|_| Error::shape(param, "a 2-d float64 array", describe(array)))?;
    let shape = array.shape();
    if let Some(cols) = cols {
        if shape[1] != cols {
            return Err(Error::shape(
                param,
                &format!("shape (steps, {cols})"),
                format!("shape ({}, {})", shape[0], shape[1]),
            ));
        }
    }
    Ok(array
        .as_array()
        .rows()
        .into_iter()
        .map(|r| r.to_vec())
        .collect())
}

/// A 1-d int64 array.
pub fn indices(param: &str, array: &Bound<'_, PyAny>) -> Result<Vec<i64>, Error> {
    let array: PyReadonlyArray1<i64> = array
        .extract()
        .map_err(|_| Error::shape(param, "a 1-d int64 array", describe(array)))?;
    Ok(array.as_array().to_vec())
}

/// A length-3 float64 vector.
pub fn vec3(param: &str, array: &Bound<'_, PyAny>) -> Result<[f64; 3], Error> {
    let v = vector(param, array, Some(3))?;
    Ok([v[0], v[1], v[2]])
}

pub fn describe(object: &Bound<'_, PyAny>) -> String {
    let shape = object.getattr("shape").ok().map(|s| s.to_string());
    let dtype = object.getattr("dtype").ok().map(|s| s.to_string());
    match (shape, dtype) {
        (Some(shape), Some(dtype)) => format!("an array of shape {shape} and dtype {dtype}"),
        _ => format!(
            "a {}",
            object
                .get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ),
    }
}

pub fn points_to_numpy<'py>(py: Python<'py>, flat: &[f64]) -> Bound<'py, PyArray2<f64>> {
    let n = flat.len() / 3;
    PyArray1::from_slice(py, flat)
        .reshape([n, 3])
        .expect("3 n values")
}

pub fn tets_to_numpy<'py>(py: Python<'py>, tets: &[[usize; 4]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = tets.iter().flatten().map(|&i| i as i64).collect();
    PyArray1::from_vec(py, flat)
        .reshape([tets.len(), 4])
        .expect("4 m values")
}

pub fn faces_to_numpy<'py>(py: Python<'py>, faces: &[[usize; 3]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = faces.iter().flatten().map(|&i| i as i64).collect();
    PyArray1::from_vec(py, flat)
        .reshape([faces.len(), 3])
        .expect("3 k values")
}

/// A cable description: a dict with "points" ((k, 3) float64, m), "model" ("springs", the
/// default, or "tendon"); a spring chain's "stiffness" (N/m), "actuation", and optionally
/// "transition", "free_node_mass" (kg) and "damping" (N s/m); a tendon's "pull" (m) or
/// "tension" (N) (at most one; neither: pull 0); and optionally "anchor_first",
/// "snap_tolerance" (m) and "outside" ("error" | "free").
pub fn cable_spec(
    index: usize,
    item: &Bound<'_, PyAny>,
) -> Result<sorofem_core::cables::CableSpec, Error> {
    use sorofem_core::cables::{CableModel, CableSpec, Outside};
    use sorofem_core::energy::TendonCommand;
    let name = |key: &str| format!("cables[{index}].{key}");
    let get = |key: &str| -> Option<Bound<'_, PyAny>> { item.get_item(key).ok() };
    let float = |key: &str, default: Option<f64>| -> Result<f64, Error> {
        match get(key) {
            Some(v) => v
                .extract::<f64>()
                .map_err(|_| Error::shape(&name(key), "a number", v.to_string())),
            None => default.ok_or_else(|| Error::invalid(&name(key), "a value", "nothing")),
        }
    };
    let points_obj = get("points")
        .ok_or_else(|| Error::invalid(&name("points"), "a (k, 3) array of points", "nothing"))?;
    let model = match get("model") {
        None => "springs".to_string(),
        Some(v) => v.extract::<String>().map_err(|_| {
            Error::shape(&name("model"), "\"springs\" or \"tendon\"", v.to_string())
        })?,
    };
    let points = points(&name("points"), &points_obj)?;
    let mut spec = match model.as_str() {
        "springs" => CableSpec::new(
            points,
            float("stiffness", None)?,
            float("actuation", Some(1.0))?,
        ),
        "tendon" => {
            let command = match (get("pull"), get("tension")) {
                (Some(_), Some(_)) => {
                    return Err(Error::invalid(
                        &name("pull"),
                        "either a pull or a tension, not both",
                        "both",
                    ))
                }
                (_, Some(_)) => TendonCommand::Tension(float("tension", None)?),
                _ => TendonCommand::Pull(float("pull", Some(0.0))?),
            };
            CableSpec::tendon(points, command)
        }
        other => {
            return Err(Error::invalid(
                &name("model"),
                "\"springs\" or \"tendon\"",
                format!("{other:?}"),
            ))
        }
    };
    let springs = spec.model == CableModel::Springs;
    spec.snap_tolerance = float("snap_tolerance", Some(0.0))?;
    if springs {
        spec.transition = float("transition", Some(spec.transition))?;
        spec.free_node_mass = float("free_node_mass", Some(0.0))?;
        spec.damping = float("damping", Some(0.0))?;
    }
    if let Some(v) = get("anchor_first") {
        spec.anchor_first = v
            .extract::<bool>()
            .map_err(|_| Error::shape(&name("anchor_first"), "a bool", v.to_string()))?;
    }
    if let Some(v) = get("outside") {
        let text: String = v
            .extract()
            .map_err(|_| Error::shape(&name("outside"), "\"error\" or \"free\"", v.to_string()))?;
        spec.outside = match text.as_str() {
            "error" => Outside::Error,
            "free" => Outside::FreeNode,
            other => {
                return Err(Error::invalid(
                    &name("outside"),
                    "\"error\" or \"free\"",
                    format!("{other:?}"),
                ))
            }
        };
    }
    Ok(spec)
}

/// A forward-sensitivity direction from a dict: blocks by name (see `zeros`, the model's blocks),
/// the material's parameters also inside a `"material"` dict, and the original keys "mu", "lam"
/// and "rho". Blocks left out are zero.
pub fn param_direction(
    direction: &Bound<'_, PyDict>,
    zeros: &sorofem_core::sensitivity::ParamVector,
) -> Result<sorofem_core::sensitivity::ParamVector, Error> {
    let mut delta = zeros.clone();
    let known: Vec<&str> = zeros.blocks.iter().map(|(n, _)| n.as_str()).collect();
    let mut set = |key: &str, name: &str, value: &Bound<'_, PyAny>| -> Result<(), Error> {
        let Some(target) = delta.get_mut(name) else {
            return Err(Error::invalid(
                "direction",
                format!(
                    "keys among {known:?}, \"material\" and the aliases \"mu\", \"lam\", \"rho\""
                ),
                format!("{key:?}"),
            ));
        };
        let len = target.len();
        *target = vector(&format!("direction[{key:?}]"), value, Some(len))?;
        Ok(())
    };
    for (key, value) in direction.iter() {
        let key: String = key
            .extract()
            .map_err(|_| Error::invalid("direction", "string keys", key.to_string()))?;
        if key == "material" {
            let inner = value.cast::<PyDict>().map_err(|_| {
                Error::shape(
                    "direction[\"material\"]",
                    "a dict of per-tet arrays by parameter name",
                    describe(&value),
                )
            })?;
            for (name, values) in inner.iter() {
                let name: String = name.extract().map_err(|_| {
                    Error::invalid("direction[\"material\"]", "string keys", name.to_string())
                })?;
                set(&format!("material.{name}"), &name, &values)?;
            }
            continue;
        }
        let name = match key.as_str() {
            "lam" => "lambda",
            "rho" => "density",
            other => other,
        };
        set(&key, name, &value)?;
    }
    Ok(delta)
}

/// The inputs of the optional terms: `terms` is a dict by term name ("cables": a list of cable
/// dicts, see [`cable_spec`]); `cables` is the constructor's original keyword for the same
/// list (not both).
pub fn term_specs(
    terms: Option<&Bound<'_, PyDict>>,
    cables: Option<&Bound<'_, pyo3::types::PyList>>,
) -> Result<sorofem_core::TermSpecs, Error> {
    let mut specs = sorofem_core::TermSpecs::default();
    let cable_list =
        |list: &Bound<'_, PyAny>| -> Result<Vec<sorofem_core::cables::CableSpec>, Error> {
            let list = list
                .cast::<pyo3::types::PyList>()
                .map_err(|_| Error::shape("cables", "a list of cable dicts", describe(list)))?;
            (list.iter().enumerate())
                .map(|(c, item)| cable_spec(c, &item))
                .collect()
        };
    if let Some(terms) = terms {
        for (key, value) in terms.iter() {
            match key.to_string().as_str() {
                "cables" if cables.is_some() => {
                    return Err(Error::invalid(
                        "cables",
                        "the cables either as the keyword or in terms, not both",
                        "both",
                    ))
                }
                "cables" => specs.cables = cable_list(&value)?,
                other => {
                    return Err(Error::invalid(
                        "terms",
                        "keys among [\"cables\"]",
                        format!("{other:?}"),
                    ))
                }
            }
        }
    }
    if let Some(cables) = cables {
        specs.cables = cable_list(cables.as_any())?;
    }
    Ok(specs)
}

/// One of `choices` (`(name, value)`), by name; `param` names the option in the error.
fn choice<T: Copy>(param: &str, given: &str, choices: &[(&str, T)]) -> Result<T, Error> {
    match choices.iter().find(|(name, _)| *name == given) {
        Some(&(_, value)) => Ok(value),
        None => {
            let names: Vec<String> = choices.iter().map(|(n, _)| format!("{n:?}")).collect();
            Err(Error::invalid(
                param,
                format!("one of {}", names.join(", ")),
                format!("{given:?}"),
            ))
        }
    }
}

pub fn orientation(name: &str) -> Result<Orientation, Error> {
    choice(
        "orientation",
        name,
        &[
            ("reorient", Orientation::Reorient),
            ("reject", Orientation::Reject),
        ],
    )
}

/// The volumetric measure: "log" (c = ln J) or "linear" (c = J - 1).
pub fn volumetric(name: &str) -> Result<Volumetric, Error> {
    choice(
        "volumetric",
        name,
        &[("log", Volumetric::Log), ("linear", Volumetric::Linear)],
    )
}

pub fn pressure_mass(name: &str) -> Result<PressureMass, Error> {
    choice(
        "pressure_mass",
        name,
        &[
            ("consistent", PressureMass::Consistent),
            ("lumped", PressureMass::Lumped),
        ],
    )
}

/// The formulation by name, with the pressure mass of the mixed one.
pub fn formulation(name: &str, mass: PressureMass) -> Result<sorofem_core::Formulation, Error> {
    use sorofem_core::Formulation;
    choice(
        "formulation",
        name,
        &[
            ("standard", Formulation::Standard),
            ("mixed", Formulation::Mixed { mass }),
        ],
    )
}

/// A string option of an options dict (`None` when absent).
pub fn string_option(
    options: Option<&Bound<'_, PyDict>>,
    key: &str,
) -> Result<Option<String>, Error> {
    let Some(value) = options.and_then(|o| o.get_item(key).ok().flatten()) else {
        return Ok(None);
    };
    value
        .extract::<String>()
        .map(Some)
        .map_err(|_| Error::shape(key, "a string", describe(&value)))
}

/// A material model by name, with its options: "neo_hookean" takes "volumetric" ("log" |
/// "linear"; default `volumetric`, the model's constructor option), "ogden" takes "terms" (1 to
/// 3, required); "mooney_rivlin" and "yeoh" take none. Unknown option keys are errors.
pub fn material_model(
    name: &str,
    options: Option<&Bound<'_, PyDict>>,
    volumetric_default: Volumetric,
) -> Result<MaterialModel, Error> {
    let model = choice(
        "model",
        name,
        &[
            (
                "neo_hookean",
                MaterialModel::NeoHookean {
                    volumetric: volumetric_default,
                },
            ),
            ("mooney_rivlin", MaterialModel::MooneyRivlin),
            ("yeoh", MaterialModel::Yeoh),
            ("ogden", MaterialModel::Ogden { terms: 0 }),
        ],
    )?;
    let known: &[&str] = match model {
        MaterialModel::NeoHookean { .. } => &["volumetric"],
        MaterialModel::Ogden { .. } => &["terms"],
        MaterialModel::MooneyRivlin | MaterialModel::Yeoh => &[],
    };
    if let Some(options) = options {
        for key in options.keys() {
            let key = key.to_string();
            if !known.contains(&key.as_str()) {
                return Err(Error::invalid(
                    "options",
                    format!("options of the {name:?} model among {known:?}"),
                    format!("{key:?}"),
                ));
            }
        }
    }
    Ok(match model {
        MaterialModel::NeoHookean { .. } => MaterialModel::NeoHookean {
            volumetric: match string_option(options, "volumetric")? {
                Some(v) => volumetric(&v)?,
                None => volumetric_default,
            },
        },
        MaterialModel::Ogden { .. } => {
            let expected = "1, 2 or 3 Ogden terms";
            let terms = options
                .and_then(|o| o.get_item("terms").ok().flatten())
                .ok_or_else(|| Error::invalid("terms", expected, "none"))?;
            let count: usize = terms
                .extract()
                .map_err(|_| Error::invalid("terms", expected, describe(&terms)))?;
            MaterialModel::ogden(count)?
        }
        other => other,
    })
}

/// Material parameters from a dict of per-tet arrays (`(m,)` float64 each), by name.
pub fn material_params(
    params: &Bound<'_, PyDict>,
    n_tets: usize,
) -> Result<Vec<(String, Vec<f64>)>, Error> {
    params
        .iter()
        .map(|(key, value)| {
            let name: String = key
                .extract()
                .map_err(|_| Error::invalid("params", "string keys", key.to_string()))?;
            let values = vector(&format!("params[{name:?}]"), &value, Some(n_tets))?;
            Ok((name, values))
        })
        .collect()
}

/// Loads from numpy: gravity (3,), nodal forces (n, 3), prescribed displacements (k, 3).
pub fn loads(
    py: Python<'_>,
    n: usize,
    gravity: &Bound<'_, PyAny>,
    forces: &Bound<'_, PyAny>,
    prescribed: &Bound<'_, PyAny>,
) -> PyResult<Loads> {
    let gravity = vec3("gravity", gravity).map_err(|e| crate::errors::to_py(py, e))?;
    let forces = points("forces", forces).map_err(|e| crate::errors::to_py(py, e))?;
    if forces.len() != n {
        return Err(crate::errors::to_py(
            py,
            sorofem_core::Error::shape(
                "forces",
                format!("({n}, 3)"),
                format!("({}, 3)", forces.len()),
            ),
        ));
    }
    let nodal_forces = forces
        .into_iter()
        .enumerate()
        .filter(|(_, f)| f.iter().any(|&v| v != 0.0))
        .collect();
    let prescribed = points("prescribed", prescribed).map_err(|e| crate::errors::to_py(py, e))?;
    Ok(Loads {
        gravity,
        nodal_forces,
        prescribed,
    })
}

/// A parameter vector as a dict: `"material"` maps each material parameter name to its per-tet
/// values, every other block sits under its own name ("density", "gravity", "cable_actuation",
/// "cable_stiffness"), and the keys of the original API stay: "mu", "lam" (Neo-Hookean) and
/// "rho" (density).
pub fn param_vector_to_dict<'py>(
    py: Python<'py>,
    p: &sorofem_core::sensitivity::ParamVector,
    material_names: &[String],
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let material = PyDict::new(py);
    for (name, values) in &p.blocks {
        let array = PyArray1::from_slice(py, values);
        if material_names.contains(name) {
            material.set_item(name, &array)?;
        } else {
            out.set_item(name, &array)?;
        }
        if let Some(alias) = legacy_param_key(name) {
            out.set_item(alias, array)?;
        }
    }
    out.set_item("material", material)?;
    Ok(out)
}

/// The original API's key of a parameter block, where it had one.
fn legacy_param_key(name: &str) -> Option<&'static str> {
    match name {
        "mu" => Some("mu"),
        "lambda" => Some("lam"),
        "density" => Some("rho"),
        _ => None,
    }
}

/// An obstacle description: a dict with "kind" and its geometry ("plane": "point", "normal";
/// "sphere": "center", "radius"; "box": "center", "half_extents", "rotation" (3, 3 rows);
/// "mesh": "vertices" (n, 3) float64, "triangles" (m, 3) int64), optionally "friction" (>= 0)
/// and "path" ((k, 4) float64 rows `[t, dx, dy, dz]`, s and m).
pub fn obstacle_spec(
    index: usize,
    item: &Bound<'_, PyAny>,
) -> Result<sorofem_core::contact::ObstacleSpec, Error> {
    use sorofem_core::contact::{Obstacle, ObstacleMesh, ObstacleSpec, Plane, Sphere};
    let name = |key: &str| format!("obstacles[{index}].{key}");
    let get = |key: &str| -> Result<Bound<'_, PyAny>, Error> {
        item.get_item(key)
            .map_err(|_| Error::invalid(&name(key), "a value", "nothing"))
    };
    let float = |key: &str| -> Result<f64, Error> {
        let v = get(key)?;
        v.extract::<f64>()
            .map_err(|_| Error::shape(&name(key), "a number", describe(&v)))
    };
    let kind: String = get("kind")?.extract().map_err(|_| {
        Error::invalid(
            &name("kind"),
            "\"plane\", \"sphere\", \"box\" or \"mesh\"",
            "not a string",
        )
    })?;
    let obstacle = match kind.as_str() {
        "plane" => Obstacle::Plane(Plane::try_new(
            vec3(&name("point"), &get("point")?)?,
            vec3(&name("normal"), &get("normal")?)?,
        )?),
        "sphere" => Obstacle::Sphere(Sphere::try_new(
            vec3(&name("center"), &get("center")?)?,
            float("radius")?,
        )?),
        "box" => {
            let rows = matrix(&name("rotation"), &get("rotation")?, Some(3))?;
            if rows.len() != 3 {
                return Err(Error::shape(
                    &name("rotation"),
                    "shape (3, 3)",
                    format!("shape ({}, 3)", rows.len()),
                ));
            }
            Obstacle::Mesh(ObstacleMesh::oriented_box(
                vec3(&name("center"), &get("center")?)?,
                vec3(&name("half_extents"), &get("half_extents")?)?,
                [0, 1, 2].map(|r| [rows[r][0], rows[r][1], rows[r][2]]),
            )?)
        }
        "mesh" => {
            let triangles: PyReadonlyArray2<i64> = get("triangles")?.extract().map_err(|_| {
                Error::shape(
                    &name("triangles"),
                    "an int64 array of shape (m, 3)",
                    "another object",
                )
            })?;
            if triangles.shape()[1] != 3 {
                return Err(Error::shape(
                    &name("triangles"),
                    "shape (m, 3)",
                    format!("shape {:?}", triangles.shape()),
                ));
            }
            let triangles: Vec<[i64; 3]> = triangles
                .as_array()
                .rows()
                .into_iter()
                .map(|r| [r[0], r[1], r[2]])
                .collect();
            Obstacle::Mesh(ObstacleMesh::try_new(
                points(&name("vertices"), &get("vertices")?)?,
                &triangles,
            )?)
        }
        other => {
            return Err(Error::invalid(
                &name("kind"),
                "\"plane\", \"sphere\", \"box\" or \"mesh\"",
                format!("{other:?}"),
            ))
        }
    };
    let friction = match item.get_item("friction") {
        Ok(v) if !v.is_none() => v
            .extract::<f64>()
            .map_err(|_| Error::shape(&name("friction"), "a number", describe(&v)))?,
        _ => 0.0,
    };
    let path = match item.get_item("path") {
        Ok(v) if !v.is_none() => matrix(&name("path"), &v, Some(4))?
            .into_iter()
            .map(|row| (row[0], [row[1], row[2], row[3]]))
            .collect(),
        _ => Vec::new(),
    };
    Ok(ObstacleSpec {
        obstacle,
        friction,
        path,
    })
}
