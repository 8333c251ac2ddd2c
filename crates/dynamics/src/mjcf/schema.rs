//! MuJoCo's MJCF schema: the element and attribute names MuJoCo knows, where it knows them. A name outside
//! it is a typo MuJoCo refuses ("Schema violation: unrecognized attribute/element") and legkit refuses too,
//! naming it, its element and line, rather than load a model that differs from the file without a word.
//! Names legkit reads but does not model pass here and are reported by the reader (warnings).

use std::collections::HashSet;
use std::sync::OnceLock;

use super::element::El;
use super::invalid;
use crate::mesh::cancel_point;
use crate::Result;

/// MuJoCo 4.0's schema table [MuJoCo, xml_native_reader.cc: MJCF, as `mujoco.mj_printSchema` prints it]:
/// rows of an element's name (or the names, space-separated, of elements that share the rest of the row: MuJoCo's
/// sensors), its cardinality (`!` exactly one, `?` at most one, `*` any number, `R` any number
/// and recursive: the element may hold itself) and its attributes; the rows between `<` and `>` are the
/// children of the row before. `body` at the top is `worldbody`, and `frame` and `replicate` are checked
/// against `body` (`ALIASES`).
#[rustfmt::skip]
const MJCF: &[&[&str]] = &[
    &["mujoco", "!", "model"],
    &["<"],
        &["compiler", "*", "alignfree", "angle", "assetdir", "autolimits", "balanceinertia", "boundinertia", "boundmass", "conflict",
            "coordinate", "discardvisual", "eulerseq", "fitaabb", "fusestatic", "inertiafromgeom", "inertiagrouprange", "meshdir",
            "passthrough", "savecanonical", "savecompiled", "saveinertial", "settotalmass", "strippath", "texturedir", "usethread"],
        &["<"],
            &["lengthrange", "?", "accel", "interval", "inttotal", "maxforce", "mode", "timeconst", "timestep", "tolrange", "useexisting",
                "uselimit"],
        &[">"],
        &["option", "*", "actuatorgroupdisable", "ccd_iterations", "ccd_tolerance", "cone", "density", "gravity", "impratio", "integrator",
            "iterations", "jacobian", "ls_iterations", "ls_tolerance", "magnetic", "noslip_iterations", "noslip_tolerance", "o_friction",
            "o_margin", "o_solimp", "o_solref", "sdf_initpoints", "sdf_iterations", "sleep_tolerance", "solver", "timestep", "tolerance",
            "viscosity", "wind"],
        &["<"],
            &["flag", "?", "actuation", "autoreset", "clampctrl", "constraint", "contact", "damper", "diagexact", "energy", "equality",
                "eulerdamp", "filterparent", "frictionloss", "fwdinv", "gravity", "invdiscrete", "ipc", "island", "limit", "midphase",
                "multiccd", "nativeccd", "override", "refsafe", "sensor", "sleep", "speculative", "spring", "warmstart"],
        &[">"],
        &["size", "*", "memory", "nconmax", "njmax", "nkey", "nstack", "nuser_actuator", "nuser_body", "nuser_cam", "nuser_geom",
            "nuser_jnt", "nuser_sensor", "nuser_site", "nuser_tendon", "nuserdata"],
        &["statistic", "*", "center", "extent", "meaninertia", "meanmass", "meansize"],
        &["visual", "*"],
        &["<"],
            &["global", "?", "azimuth", "bvactive", "cameraid", "elevation", "ellipsoidinertia", "fovy", "glow", "ipd", "linewidth",
                "offheight", "offwidth", "orthographic", "realtime"],
            &["quality", "?", "numquads", "numslices", "numstacks", "offsamples", "shadowsize"],
            &["headlight", "?", "active", "ambient", "diffuse", "specular"],
            &["map", "?", "actuatortendon", "alpha", "fogend", "fogstart", "force", "haze", "shadowclip", "shadowscale", "stiffness",
                "stiffnessrot", "torque", "zfar", "znear"],
            &["scale", "?", "actuatorlength", "actuatorwidth", "camera", "com", "connect", "constraint", "contactheight", "contactwidth",
                "forcewidth", "framelength", "framewidth", "frustum", "jointlength", "jointwidth", "light", "selectpoint", "slidercrank"],
            &["rgba", "?", "actuator", "actuatornegative", "actuatorpositive", "bv", "bvactive", "camera", "com", "connect", "constraint",
                "contactforce", "contactfriction", "contactgap", "contactpoint", "contacttorque", "crankbroken", "fog", "force", "frustum",
                "haze", "inertia", "joint", "light", "rangefinder", "selectpoint", "slidercrank"],
        &[">"],
        &["default", "R", "class"],
        &["<"],
            &["mesh", "?", "inertia", "maxhullvert", "scale"],
            &["texture", "?", "builtin", "colorspace", "embed", "gridlayout", "gridsize", "height", "hflip", "mark", "markrgb", "nchannel",
                "random", "rgb1", "rgb2", "type", "vflip", "width"],
            &["material", "?", "emission", "metallic", "reflectance", "rgba", "roughness", "shininess", "specular", "texrepeat", "texture",
                "texuniform"],
            &["<"],
                &["layer", "*", "role", "texture"],
            &[">"],
            &["joint", "?", "actuatorfrclimited", "actuatorfrcrange", "actuatorgravcomp", "armature", "axis", "damping", "frictionloss",
                "group", "limited", "margin", "pos", "range", "ref", "solimpfriction", "solimplimit", "solreffriction", "solreflimit",
                "springdamper", "springref", "springyield", "stiffness", "type", "user"],
            &["geom", "?", "adhesion", "axisangle", "castshadow", "conaffinity", "condim", "contype", "density", "euler", "fitscale",
                "fluidcoef", "fluidshape", "friction", "fromto", "gap", "group", "hfield", "margin", "mass", "material", "mesh", "pos",
                "priority", "quat", "rgba", "shellinertia", "size", "solimp", "solmix", "solref", "surfacevel", "type", "user", "xyaxes",
                "zaxis"],
            &["site", "?", "axisangle", "euler", "fromto", "group", "material", "mesh", "pos", "quat", "rgba", "size", "type", "user",
                "xyaxes", "zaxis"],
            &["camera", "?", "axisangle", "euler", "focal", "focalpixel", "fovy", "ipd", "mode", "output", "pos", "principal",
                "principalpixel", "projection", "quat", "resolution", "sensorsize", "user", "xyaxes", "zaxis"],
            &["light", "?", "active", "ambient", "attenuation", "bulbradius", "castshadow", "cutoff", "diffuse", "dir", "directional",
                "exponent", "intensity", "mode", "pos", "range", "softness", "specular", "type"],
            &["pair", "?", "adhesion", "condim", "friction", "gap", "margin", "solimp", "solref", "solreffriction"],
            &["equality", "?", "active", "solimp", "solref"],
            &["tendon", "?", "actuatorfrclimited", "actuatorfrcrange", "armature", "damping", "frictionloss", "group", "limited", "margin",
                "material", "range", "rgba", "solimpfriction", "solimplimit", "solreffriction", "solreflimit", "springlength",
                "springyield", "stiffness", "user", "width"],
            &["general", "?", "actdim", "actearly", "actlimited", "actrange", "armature", "biasprm", "biastype", "cranklength",
                "ctrllimited", "ctrlrange", "damping", "delay", "dynprm", "dyntype", "ffrange", "forcelimited", "forcerange", "gainprm",
                "gaintype", "gear", "group", "inheritrange", "input", "interp", "nsample", "user", "velrange"],
            &["motor", "?", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "delay", "forcelimited", "forcerange", "gear",
                "group", "interp", "nsample", "user"],
            &["position", "?", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "dampratio", "delay", "forcelimited",
                "forcerange", "gear", "group", "inheritrange", "interp", "kp", "kv", "nsample", "timeconst", "user"],
            &["velocity", "?", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "delay", "forcelimited", "forcerange",
                "gear", "group", "interp", "kv", "nsample", "user"],
            &["intvelocity", "?", "actlimited", "actrange", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "dampratio",
                "delay", "forcelimited", "forcerange", "gear", "group", "inheritrange", "interp", "kp", "kv", "nsample", "user"],
            &["orientation", "?", "ctrlrange", "dampratio", "delay", "forcelimited", "forcerange", "group", "input", "interp", "kp", "kv",
                "nsample", "user"],
            &["pid", "?", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "dampratio", "delay", "ffrange", "forcelimited",
                "forcerange", "gear", "group", "imax", "inheritrange", "input", "interp", "ki", "kp", "kv", "nsample", "posrange",
                "slewmax", "user", "velrange"],
            &["damper", "?", "armature", "cranklength", "ctrlrange", "damping", "delay", "forcelimited", "forcerange", "gear", "group",
                "interp", "kv", "nsample", "user"],
            &["cylinder", "?", "area", "armature", "bias", "cranklength", "ctrllimited", "ctrlrange", "damping", "delay", "diameter",
                "forcelimited", "forcerange", "gear", "group", "interp", "nsample", "timeconst", "user"],
            &["muscle", "?", "armature", "cranklength", "ctrllimited", "ctrlrange", "damping", "delay", "force", "forcelimited",
                "forcerange", "fpmax", "fvmax", "gear", "group", "interp", "lmax", "lmin", "nsample", "range", "scale", "timeconst", "user",
                "vmax"],
            &["adhesion", "?", "ctrlrange", "delay", "forcelimited", "forcerange", "gain", "group", "interp", "nsample", "user"],
            &["dcmotor", "?", "armature", "cogging", "controller", "cranklength", "ctrllimited", "ctrlrange", "damping", "delay", "gear",
                "group", "inductance", "input", "interp", "lugre", "motorconst", "nominal", "nsample", "resistance", "saturation",
                "thermal", "user"],
        &[">"],
        &["extension", "*"],
        &["<"],
            &["plugin", "*", "plugin"],
            &["<"],
                &["instance", "*", "name"],
                &["<"], &["config", "*", "key", "value"], &[">"],
            &[">"],
        &[">"],
        &["asset", "*"],
        &["<"],
            &["mesh", "*", "builtin", "class", "content_type", "face", "file", "inertia", "material", "maxhullvert", "name", "normal",
                "params", "refpos", "refquat", "scale", "smoothnormal", "texcoord", "vertex"],
            &["<"],
                &["plugin", "*", "instance", "plugin"],
                &["<"], &["config", "*", "key", "value"], &[">"],
            &[">"],
            &["hfield", "*", "content_type", "elevation", "file", "name", "ncol", "nrow", "size"],
            &["skin", "*", "face", "file", "group", "inflate", "material", "name", "rgba", "texcoord", "vertex"],
            &["<"],
                &["bone", "*", "bindpos", "bindquat", "body", "vertid", "vertweight"],
            &[">"],
            &["texture", "*", "builtin", "class", "colorspace", "content_type", "embed", "file", "fileback", "filedown", "filefront",
                "fileleft", "fileright", "fileup", "gridlayout", "gridsize", "height", "hflip", "mark", "markrgb", "name", "nchannel",
                "random", "rgb1", "rgb2", "type", "vflip", "width"],
            &["material", "*", "class", "emission", "metallic", "name", "reflectance", "rgba", "roughness", "shininess", "specular",
                "texrepeat", "texture", "texuniform"],
            &["<"],
                &["layer", "*", "role", "texture"],
            &[">"],
            &["model", "*", "content_type", "file", "name"],
        &[">"],
        &["body", "R", "axisangle", "childclass", "euler", "fuse", "gravcomp", "mocap", "name", "pos", "quat", "simple", "sleep", "user",
            "xyaxes", "zaxis"],
        &["<"],
            &["inertial", "?", "axisangle", "diaginertia", "euler", "fullinertia", "mass", "pos", "quat", "xyaxes", "zaxis"],
            &["joint", "*", "actuatorfrclimited", "actuatorfrcrange", "actuatorgravcomp", "armature", "axis", "class", "damping",
                "frictionloss", "group", "limited", "margin", "name", "pos", "range", "ref", "solimpfriction", "solimplimit",
                "solreffriction", "solreflimit", "springdamper", "springref", "springyield", "stiffness", "type", "user"],
            &["freejoint", "*", "align", "group", "name"],
            &["geom", "*", "adhesion", "axisangle", "castshadow", "class", "conaffinity", "condim", "contype", "density", "euler",
                "fitscale", "fluidcoef", "fluidshape", "friction", "fromto", "gap", "group", "hfield", "margin", "mass", "material", "mesh",
                "name", "pos", "priority", "quat", "rgba", "shellinertia", "size", "solimp", "solmix", "solref", "surfacevel", "type",
                "user", "xyaxes", "zaxis"],
            &["<"],
                &["plugin", "*", "instance", "plugin"],
                &["<"], &["config", "*", "key", "value"], &[">"],
            &[">"],
            &["attach", "*", "body", "frame", "model", "prefix"],
            &["site", "*", "axisangle", "class", "euler", "fromto", "group", "material", "mesh", "name", "pos", "quat", "rgba", "size",
                "type", "user", "xyaxes", "zaxis"],
            &["camera", "*", "axisangle", "class", "euler", "focal", "focalpixel", "fovy", "ipd", "mode", "name", "output", "pos",
                "principal", "principalpixel", "projection", "quat", "resolution", "sensorsize", "target", "user", "xyaxes", "zaxis"],
            &["light", "*", "active", "ambient", "attenuation", "bulbradius", "castshadow", "class", "cutoff", "diffuse", "dir",
                "directional", "exponent", "intensity", "mode", "name", "pos", "range", "softness", "specular", "target", "texture", "type"],
            &["plugin", "*", "instance", "plugin"],
            &["<"], &["config", "*", "key", "value"], &[">"],
            &["flexcomp", "*", "axisangle", "cellcount", "count", "dim", "dof", "element", "euler", "file", "flatskin", "group",
                "inertiabox", "mass", "material", "mesh", "name", "origin", "point", "pos", "quat", "radius", "rgba", "rigid", "scale",
                "spacing", "texcoord", "type", "xyaxes", "zaxis"],
            &["<"],
                &["edge", "?", "damping", "equality", "solimp", "solref", "stiffness"],
                &["elasticity", "?", "damping", "elastic2d", "poisson", "section", "sectionsize", "shear", "thickness", "yield", "young"],
                &["contact", "?", "activelayers", "conaffinity", "condim", "contype", "friction", "gap", "margin", "passive", "priority",
                    "selfcollide", "solimp", "solmix", "solref"],
                &["pin", "*", "grid", "gridrange", "id", "range"],
                &["plugin", "*", "instance", "plugin"],
                &["<"], &["config", "*", "key", "value"], &[">"],
            &[">"],
        &[">"],
        &["deformable", "*"],
        &["<"],
            &["flex", "*", "body", "cellcount", "dim", "dof", "element", "elemtexcoord", "flatskin", "group", "material", "name", "node",
                "nodecoord", "radius", "rgba", "texcoord", "vertex"],
            &["<"],
                &["contact", "?", "activelayers", "conaffinity", "condim", "contype", "friction", "gap", "margin", "passive", "priority",
                    "selfcollide", "solimp", "solmix", "solref"],
                &["edge", "?", "damping", "stiffness"],
                &["elasticity", "?", "damping", "elastic2d", "poisson", "section", "sectionsize", "shear", "thickness", "yield", "young"],
            &[">"],
            &["skin", "*", "face", "file", "group", "inflate", "material", "name", "rgba", "texcoord", "vertex"],
            &["<"],
                &["bone", "*", "bindpos", "bindquat", "body", "vertid", "vertweight"],
            &[">"],
        &[">"],
        &["contact", "*"],
        &["<"],
            &["pair", "*", "adhesion", "class", "condim", "friction", "gap", "geom1", "geom2", "margin", "name", "solimp", "solref",
                "solreffriction"],
            &["exclude", "*", "body1", "body2", "name"],
        &[">"],
        &["tendon", "*"],
        &["<"],
            &["spatial", "*", "actuatorfrclimited", "actuatorfrcrange", "armature", "class", "damping", "frictionloss", "group", "limited",
                "margin", "material", "name", "range", "rgba", "solimpfriction", "solimplimit", "solreffriction", "solreflimit",
                "springlength", "springyield", "stiffness", "user", "width"],
            &["<"],
                &["site", "*", "site"],
                &["geom", "*", "geom", "sidesite"],
                &["pulley", "*", "divisor"],
            &[">"],
            &["fixed", "*", "actuatorfrclimited", "actuatorfrcrange", "armature", "class", "damping", "frictionloss", "group", "limited",
                "margin", "name", "range", "solimpfriction", "solimplimit", "solreffriction", "solreflimit", "springlength", "springyield",
                "stiffness", "user"],
            &["<"],
                &["joint", "*", "coef", "joint"],
            &[">"],
        &[">"],
        &["equality", "*"],
        &["<"],
            &["connect", "*", "active", "anchor", "body1", "body2", "class", "name", "site1", "site2", "solimp", "solref"],
            &["weld", "*", "active", "anchor", "body1", "body2", "class", "name", "relpose", "site1", "site2", "solimp", "solref",
                "torquescale"],
            &["joint", "*", "active", "class", "joint1", "joint2", "name", "polycoef", "solimp", "solref"],
            &["tendon", "*", "active", "class", "name", "polycoef", "solimp", "solref", "tendon1", "tendon2"],
            &["flex", "*", "active", "class", "flex", "name", "solimp", "solref"],
            &["flexstrain", "*", "active", "cell", "class", "flex", "name", "solimp", "solref"],
        &[">"],
        &["actuator", "*"],
        &["<"],
            &["general", "*", "actdim", "actearly", "actlimited", "actrange", "armature", "biasprm", "biastype", "body", "class",
                "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "delay", "dynprm", "dyntype", "ffrange", "forcelimited",
                "forcerange", "gainprm", "gaintype", "gear", "group", "inheritrange", "input", "interp", "joint", "jointinparent",
                "lengthrange", "name", "nsample", "refsite", "site", "slidersite", "tendon", "user", "velrange"],
            &["motor", "*", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "delay", "forcelimited",
                "forcerange", "gear", "group", "interp", "joint", "jointinparent", "lengthrange", "name", "nsample", "refsite", "site",
                "slidersite", "tendon", "user"],
            &["position", "*", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "dampratio", "delay",
                "forcelimited", "forcerange", "gear", "group", "inheritrange", "interp", "joint", "jointinparent", "kp", "kv",
                "lengthrange", "name", "nsample", "refsite", "site", "slidersite", "tendon", "timeconst", "user"],
            &["velocity", "*", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "delay",
                "forcelimited", "forcerange", "gear", "group", "interp", "joint", "jointinparent", "kv", "lengthrange", "name", "nsample",
                "refsite", "site", "slidersite", "tendon", "user"],
            &["intvelocity", "*", "actlimited", "actrange", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange",
                "damping", "dampratio", "delay", "forcelimited", "forcerange", "gear", "group", "inheritrange", "interp", "joint",
                "jointinparent", "kp", "kv", "lengthrange", "name", "nsample", "refsite", "site", "slidersite", "tendon", "user"],
            &["orientation", "*", "class", "ctrlrange", "dampratio", "delay", "forcelimited", "forcerange", "group", "input", "interp",
                "joint", "kp", "kv", "name", "nsample", "refsite", "site", "user"],
            &["pid", "*", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "dampratio", "delay",
                "ffrange", "forcelimited", "forcerange", "gear", "group", "imax", "inheritrange", "input", "interp", "joint",
                "jointinparent", "ki", "kp", "kv", "lengthrange", "name", "nsample", "posrange", "refsite", "site", "slewmax", "slidersite",
                "tendon", "user", "velrange"],
            &["damper", "*", "armature", "class", "cranklength", "cranksite", "ctrlrange", "damping", "delay", "forcelimited", "forcerange",
                "gear", "group", "interp", "joint", "jointinparent", "kv", "lengthrange", "name", "nsample", "refsite", "site",
                "slidersite", "tendon", "user"],
            &["cylinder", "*", "area", "armature", "bias", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping",
                "delay", "diameter", "forcelimited", "forcerange", "gear", "group", "interp", "joint", "jointinparent", "lengthrange",
                "name", "nsample", "refsite", "site", "slidersite", "tendon", "timeconst", "user"],
            &["muscle", "*", "armature", "class", "cranklength", "cranksite", "ctrllimited", "ctrlrange", "damping", "delay", "force",
                "forcelimited", "forcerange", "fpmax", "fvmax", "gear", "group", "interp", "joint", "jointinparent", "lengthrange", "lmax",
                "lmin", "name", "nsample", "range", "scale", "slidersite", "tausmooth", "tendon", "timeconst", "user", "vmax"],
            &["adhesion", "*", "body", "class", "ctrlrange", "delay", "forcelimited", "forcerange", "gain", "group", "interp", "name",
                "nsample", "user"],
            &["dcmotor", "*", "armature", "class", "cogging", "controller", "cranklength", "cranksite", "ctrllimited", "ctrlrange",
                "damping", "delay", "gear", "group", "inductance", "input", "interp", "joint", "jointinparent", "lengthrange", "lugre",
                "motorconst", "name", "nominal", "nsample", "refsite", "resistance", "saturation", "site", "slidersite", "tendon",
                "thermal", "user"],
            &["plugin", "*", "actdim", "actearly", "actlimited", "actrange", "armature", "class", "cranklength", "cranksite", "ctrllimited",
                "ctrlrange", "damping", "delay", "dynprm", "dyntype", "forcelimited", "forcerange", "gear", "group", "instance", "interp",
                "joint", "jointinparent", "lengthrange", "name", "nsample", "plugin", "site", "slidersite", "tendon", "user"],
            &["<"], &["config", "*", "key", "value"], &[">"],
        &[">"],
        &["sensor", "*"],
        &["<"],
            &["touch accelerometer velocimeter gyro force torque magnetometer", "*", "cutoff", "delay", "interp", "interval", "name", "noise",
                "nsample", "site", "user"],
            &["camprojection", "*", "camera", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "site", "user"],
            &["rangefinder", "*", "camera", "cutoff", "data", "delay", "interp", "interval", "name", "noise", "nsample", "site", "user"],
            &["jointpos jointvel", "*", "cutoff", "delay", "interp", "interval", "joint", "name", "noise", "nsample", "user"],
            &["tendonpos tendonvel", "*", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "tendon", "user"],
            &["actuatorpos actuatorvel actuatorfrc", "*", "actuator", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "user"],
            &["jointactuatorfrc", "*", "cutoff", "delay", "interp", "interval", "joint", "name", "noise", "nsample", "user"],
            &["tendonactuatorfrc", "*", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "tendon", "user"],
            &["ballquat ballangvel jointlimitpos jointlimitvel jointlimitfrc", "*", "cutoff", "delay", "interp", "interval", "joint", "name", "noise",
                "nsample", "user"],
            &["tendonlimitpos tendonlimitvel tendonlimitfrc", "*", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "tendon",
                "user"],
            &["framepos framequat framexaxis frameyaxis framezaxis framelinvel frameangvel", "*", "cutoff", "delay", "interp", "interval", "name",
                "noise", "nsample", "objname", "objtype", "refname", "reftype", "user"],
            &["framelinacc frameangacc", "*", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "objname", "objtype", "user"],
            &["subtreecom subtreelinvel subtreeangmom", "*", "body", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "user"],
            &["insidesite", "*", "cutoff", "delay", "enclosed", "interp", "interval", "name", "noise", "nsample", "objname", "objtype",
                "site", "user"],
            &["distance normal fromto", "*", "body1", "body2", "cutoff", "delay", "geom1", "geom2", "interp", "interval", "name", "noise", "nsample",
                "user"],
            &["contact", "*", "body1", "body2", "cutoff", "data", "delay", "geom1", "geom2", "interp", "interval", "name", "noise",
                "nsample", "num", "reduce", "site", "subtree1", "subtree2", "user"],
            &["e_potential e_kinetic clock", "*", "cutoff", "delay", "interp", "interval", "name", "noise", "nsample", "user"],
            &["tactile", "*", "cutoff", "delay", "geom", "interp", "interval", "mesh", "name", "nsample", "user"],
            &["user", "*", "cutoff", "datatype", "dim", "name", "needstage", "noise", "objname", "objtype", "user"],
            &["plugin", "*", "cutoff", "instance", "name", "objname", "objtype", "plugin", "refname", "reftype", "user"],
            &["<"], &["config", "*", "key", "value"], &[">"],
        &[">"],
        &["custom", "*"],
        &["<"],
            &["numeric", "*", "data", "name", "size"],
            &["text", "*", "data", "name"],
            &["tuple", "*", "name"],
            &["<"],
                &["element", "*", "objname", "objtype", "prm"],
            &[">"],
        &[">"],
        &["keyframe", "*"],
        &["<"],
            &["key", "*", "act", "ctrl", "mpos", "mquat", "name", "plastic", "qpos", "qvel", "time"],
        &[">"],
    &[">"],
];

/// What MuJoCo checks against the `body` row (mjXSchema::NameMatch), with each its own attributes
/// [MuJoCo, mjcf.schema: worldbody, frame, replicate]. MuJoCo's validator skips the attributes and contents
/// of frames and replicates; legkit checks them, so a typo inside a frame is refused too.
const ALIASES: &[(&str, &[&str])] = &[
    ("worldbody", &[]),
    ("frame", &["name", "childclass", "pos", "quat", "axisangle", "xyaxes", "zaxis", "euler"]),
    ("replicate", &["count", "offset", "euler", "sep", "childclass"]),
];

/// One element of the schema.
struct Row {
    name: &'static str,
    /// `?` or `!`: it appears at most once in its parent.
    unique: bool,
    /// `R`: it may hold itself.
    recursive: bool,
    attributes: HashSet<&'static str>,
    children: Vec<Row>,
}

/// The schema's root, `<mujoco>`, built from `MJCF` on first use.
fn root() -> &'static Row {
    static ROOT: OnceLock<Row> = OnceLock::new();
    ROOT.get_or_init(|| {
        let mut at = 0;
        let mut rows = rows(&mut at);
        assert!(at == MJCF.len() && rows.len() == 1, "MJCF is one balanced tree");
        rows.remove(0)
    })
}

/// The rows from `MJCF[*at]` to the `>` that closes them (or the end), with their children.
fn rows(at: &mut usize) -> Vec<Row> {
    let mut rows: Vec<Row> = Vec::new();
    while let Some(&row) = MJCF.get(*at) {
        *at += 1;
        match row {
            [">"] => break,
            ["<"] => rows.last_mut().expect("a row before each <").children = self::rows(at),
            [names, cardinality, attributes @ ..] => rows.extend(names.split(' ').map(|name| Row {
                name,
                unique: matches!(*cardinality, "?" | "!"),
                recursive: *cardinality == "R",
                attributes: attributes.iter().copied().collect(),
                children: Vec::new(),
            })),
            _ => unreachable!("every row of MJCF has a name and a cardinality"),
        }
    }
    rows
}

/// Checks `root` (`<mujoco>`, includes spliced in, as MuJoCo checks it) against the schema: an unknown
/// element or attribute, or a second of an element that appears at most once, is an error naming it.
pub(super) fn check(root: &El) -> Result<()> {
    check_element(root, self::root(), None, &mut 0)
}

/// Checks `el` against `row`, with the attributes `alias` when given (not the row's).
fn check_element(el: &El, row: &Row, alias: Option<&[&str]>, seen: &mut usize) -> Result<()> {
    *seen += 1;
    cancel_point("from_mjcf", *seen)?;
    let known = |key: &str| alias.map_or_else(|| row.attributes.contains(key), |names| names.contains(&key));
    if let Some((key, _)) = el.attrs.iter().find(|(key, _)| !known(key)) {
        return Err(violation(el, &format!("unrecognized attribute {:?} in <{}>", key.as_str(), el.tag)));
    }
    let mut unique: Vec<&str> = Vec::new();
    for child in &el.children {
        let tag = child.tag.as_str();
        let Some((child_row, child_alias)) = child_row(row, tag) else {
            return Err(violation(child, &format!("unrecognized element <{tag}> in <{}>", el.tag)));
        };
        if child_row.unique {
            if unique.contains(&tag) {
                return Err(violation(child, &format!("a second <{tag}> in <{}>, which MuJoCo allows once", el.tag)));
            }
            unique.push(tag);
        }
        check_element(child, child_row, child_alias, seen)?;
    }
    Ok(())
}

/// The row a child `tag` of an element of `row` is checked against, and its own attributes if it is an alias.
fn child_row<'s>(row: &'s Row, tag: &str) -> Option<(&'s Row, Option<&'static [&'static str]>)> {
    let alias = ALIASES.iter().find(|(name, _)| *name == tag).map(|&(_, names)| names);
    match (row.name, tag) {
        // The top `body` row is the world body's: a body there is unknown, as in MuJoCo.
        ("mujoco", "worldbody") => row.children.iter().find(|c| c.name == "body").map(|body| (body, alias)),
        ("mujoco", "body") => None,
        ("body", "frame" | "replicate") => Some((row, alias)),
        _ if row.recursive && tag == row.name => Some((row, None)),
        _ => row.children.iter().find(|c| c.name == tag).map(|c| (c, None)),
    }
}

fn violation(el: &El, what: &str) -> crate::Error {
    invalid(format!("schema violation at line {} of {}: {what} (MuJoCo refuses it)", el.at.line, el.at.label))
}

#[cfg(test)]
mod tests {
    use crate::mjcf::{load_mjcf, MjcfOptions};

    fn error(xml: &str) -> String {
        load_mjcf(xml, &MjcfOptions::default()).unwrap_err().to_string()
    }

    #[test]
    fn the_table_is_one_tree_under_mujoco() {
        let root = super::root();
        assert_eq!((root.name, root.children.len()), ("mujoco", 17));
        let body = root.children.iter().find(|c| c.name == "body").unwrap();
        assert!(body.recursive && body.children.iter().any(|c| c.name == "inertial" && c.unique));
    }

    #[test]
    fn typos_are_refused_naming_the_name_its_element_and_line() {
        let body = |inner: &str| format!("<mujoco>\n<worldbody>\n<body>\n{inner}\n</body></worldbody></mujoco>");
        for (xml, expected) in [
            (body("<joint dampng='1'/>"), "line 4 of <string>: unrecognized attribute \"dampng\" in <joint>"),
            (body("<geom size='1' desnity='10'/>"), "line 4 of <string>: unrecognized attribute \"desnity\" in <geom>"),
            (body("<inertial mas='5'/>"), "line 4 of <string>: unrecognized attribute \"mas\" in <inertial>"),
            ("<mujoco>\n<compiler angel='radian'/></mujoco>".into(), "line 2 of <string>: unrecognized attribute \"angel\" in <compiler>"),
            (body("<jiont/>"), "line 4 of <string>: unrecognized element <jiont> in <body>"),
            ("<mujoco><foo/></mujoco>".into(), "unrecognized element <foo> in <mujoco>"),
            ("<mujoco><body/></mujoco>".into(), "unrecognized element <body> in <mujoco>"),
            ("<mujoco><worldbody pos='0 0 1'/></mujoco>".into(), "unrecognized attribute \"pos\" in <worldbody>"),
            // Names known elsewhere: `name` and `class` are not default attributes, `count` is a replicate's.
            ("<mujoco><default><joint name='j'/></default></mujoco>".into(), "unrecognized attribute \"name\" in <joint>"),
            ("<mujoco><worldbody><body count='2'/></worldbody></mujoco>".into(), "unrecognized attribute \"count\" in <body>"),
            // Inside frames and replicates, which MuJoCo's validator skips.
            ("<mujoco><worldbody><frame><geom size='1' desnity='1'/></frame></worldbody></mujoco>".into(), "\"desnity\" in <geom>"),
            ("<mujoco><worldbody><replicate count='2' offst='1 0 0'/></worldbody></mujoco>".into(), "\"offst\" in <replicate>"),
            (body("<inertial mass='1' diaginertia='1 1 1'/><inertial mass='1' diaginertia='1 1 1'/>"), "a second <inertial> in <body>"),
        ] {
            let message = error(&xml);
            assert!(message.starts_with("mjcf: schema violation at ") && message.contains(expected), "{xml}: {message}");
        }
    }

    #[test]
    fn known_names_pass_in_bodies_frames_replicates_and_nested_defaults() {
        let xml = "<mujoco model='m'><compiler angle='radian'/><default class='main'><default class='a'><joint damping='1'/>\
                   <default class='b'><geom density='10'/></default></default></default><worldbody><frame pos='1 0 0'>\
                   <replicate count='2' offset='1 0 0' sep='_'><body name='b' childclass='a'><joint/><geom class='b' size='0.1'/>\
                   </body></replicate></frame></worldbody></mujoco>";
        let loaded = load_mjcf(xml, &MjcfOptions::default()).unwrap();
        assert_eq!(loaded.model.nq(), 2);
    }
}
