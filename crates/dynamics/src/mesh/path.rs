//! Where a mesh file a URDF names lies: `package://` and `model://` names through the package folders, relative
//! names, symbolic links checked.

use std::path::{Component, Path, PathBuf};

use crate::{Error, Result};

/// Where a URDF's mesh `filename` lies, read as Pinocchio and ROS read it:
///
/// - `package://name/rest` is `dir/name/rest` (or `dir/rest` when `dir` is the package `name` itself) for the
///   first such file over `package_dirs`, then `ROS_PACKAGE_PATH`'s folders,
///   then each of `AMENT_PREFIX_PATH`'s prefixes' `share/` (a sourced ROS 2 workspace), then the URDF folder's
///   ancestors (`urdf_dir`). Empty segments are skipped, so `package:///name/rest` (as example-robot-data
///   writes it) is the same name; `model://` (Gazebo's) is read as `package://`. The name may not climb
///   (`..`): it is refused (`Error::Invalid` naming `filename`). See `confined` for symbolic links.
/// - `file://path` and absolute paths are read as written.
/// - A relative path is taken against `urdf_dir` (the working folder if None), then, if it does not climb,
///   against each of `package_dirs` (confined to it, as a package name is).
pub fn resolve_mesh(filename: &str, urdf_dir: Option<&Path>, package_dirs: &[PathBuf]) -> Result<PathBuf> {
    let outside = || Error::invalid("filename", format!("{filename:?} names a file outside its package (only names below it are allowed)"));
    if let Some(rest) = ["package://", "model://"].iter().find_map(|scheme| filename.strip_prefix(scheme)) {
        let mut parts = Vec::new();
        for component in Path::new(rest).components() {
            match component {
                Component::Normal(part) => parts.push(part),
                Component::RootDir | Component::CurDir => {}
                // `..` or a drive would reach files outside the package (which the viewer would then embed).
                Component::ParentDir | Component::Prefix(_) => return Err(outside()),
            }
        }
        let Some((&package, inside)) = parts.split_first() else {
            return Err(Error::invalid("filename", format!("{filename:?} names no package")));
        };
        let inside: PathBuf = inside.iter().collect();
        let paths = |variable: &str| std::env::var_os(variable).map(|p| std::env::split_paths(&p).collect::<Vec<_>>()).unwrap_or_default();
        let ament_shares = paths("AMENT_PREFIX_PATH").into_iter().map(|prefix| prefix.join("share"));
        let ancestors = urdf_dir.into_iter().flat_map(Path::ancestors).map(Path::to_path_buf);
        let mut searched = Vec::new();
        for dir in package_dirs.iter().cloned().chain(paths("ROS_PACKAGE_PATH")).chain(ament_shares).chain(ancestors) {
            let itself = dir.file_name().is_some_and(|name| name == package);
            for root in [dir.join(package)].into_iter().chain(itself.then(|| dir.clone())) {
                let candidate = root.join(&inside);
                if candidate.is_file() {
                    return confined(filename, candidate, &root);
                }
            }
            searched.push(dir.display().to_string());
        }
        return Err(Error::invalid("package_dirs", format!("{filename:?} is in none of {}", searched.join(", "))));
    }
    let path = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
    let beside = match urdf_dir {
        Some(dir) if path.is_relative() => dir.join(path),
        _ => path.to_path_buf(),
    };
    if beside.is_file() {
        return Ok(beside);
    }
    // Pinocchio's fallback for a relative name: each package folder, which the name may not leave.
    if path.is_relative() && path.components().all(|c| matches!(c, Component::Normal(_) | Component::CurDir)) {
        if let Some(dir) = package_dirs.iter().find(|dir| dir.join(path).is_file()) {
            return confined(filename, dir.join(path), dir);
        }
    }
    Err(Error::invalid("mesh", format!("{filename:?}: no such file ({})", beside.display())))
}

/// `candidate`, a name below `root`, once its symbolic links are checked. They are followed wherever they lead,
/// as Pinocchio and ROS follow them: a colcon `--symlink-install` share folder links each installed file to
/// its source, a catkin devel space links into `src/`, and the user made those links, not the URDF. A name
/// cannot climb out of its package (the callers refuse `..`), but a package from an archive may bring links
/// of its own: one that leads out of the package must reach a file of the name's kind (the same extension,
/// as colcon's and catkin's links keep it), never a key or a configuration file that the viewer would embed.
fn confined(filename: &str, candidate: PathBuf, root: &Path) -> Result<PathBuf> {
    let real = |path: &Path| path.canonicalize().map_err(|e| Error::invalid("filename", format!("{filename:?}: {}: {e}", path.display())));
    let (file, folder) = (real(&candidate)?, real(root)?);
    let extension = |path: &Path| path.extension().map(|e| e.to_ascii_lowercase());
    if !file.starts_with(&folder) && (extension(&candidate).is_none() || extension(&file) != extension(&candidate)) {
        return Err(Error::invalid(
            "filename",
            format!(
                "{filename:?} leads outside its package {} to a file of another kind (a symbolic link reaches {})",
                folder.display(),
                file.display()
            ),
        ));
    }
    Ok(candidate)
}
