//! Compiles every `glsl/**/*.comp` to SPIR-V 1.5 (Vulkan 1.2) with shaderc, reflects each
//! module with rspirv-reflect, and writes `$OUT_DIR/kernel_table.rs`: one entry per kernel
//! with its SPIR-V, bindings, push-constant size and workgroup size. The host builds every
//! descriptor layout from this table; none is written by hand.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use rspirv_reflect::{BindingCount, DescriptorType, Reflection};

struct Kernel {
    /// Path under glsl/ without extension, e.g. "sort/count".
    name: String,
    spv_file: PathBuf,
    /// (binding, name, is_uniform)
    bindings: Vec<(u32, String, bool)>,
    push_constant_size: u32,
    workgroup_size: (u32, u32, u32),
}

fn fail(msg: String) -> ! {
    eprintln!("\n{msg}\n");
    std::process::exit(1);
}

fn find_shaders(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", dir.display())))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            find_shaders(&p, out);
        } else if p.extension().is_some_and(|e| e == "comp") {
            out.push(p);
        }
    }
}

fn compile(
    compiler: &shaderc::Compiler,
    path: &Path,
    source: &str,
    common: &Path,
    optimize: bool,
) -> Vec<u32> {
    let mut opts = shaderc::CompileOptions::new().unwrap();
    opts.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_2 as u32,
    );
    // rspirv-reflect fails on SPIR-V 1.6 (docs/TOOLCHAIN.md): stay on 1.5.
    opts.set_target_spirv(shaderc::SpirvVersion::V1_5);
    opts.set_source_language(shaderc::SourceLanguage::GLSL);
    opts.set_optimization_level(if optimize {
        shaderc::OptimizationLevel::Performance
    } else {
        shaderc::OptimizationLevel::Zero
    });
    opts.set_warnings_as_errors();
    let common = common.to_path_buf();
    opts.set_include_callback(move |name, kind, requester, _depth| {
        let local = Path::new(requester).parent().map(|d| d.join(name));
        let candidates: Vec<PathBuf> = match kind {
            shaderc::IncludeType::Relative => {
                local.into_iter().chain([common.join(name)]).collect()
            }
            shaderc::IncludeType::Standard => vec![common.join(name)],
        };
        for c in candidates {
            if let Ok(content) = fs::read_to_string(&c) {
                return Ok(shaderc::ResolvedInclude {
                    resolved_name: c.to_string_lossy().into_owned(),
                    content,
                });
            }
        }
        Err(format!(
            "include \"{name}\" not found (looked beside {requester} and in glsl/common/)"
        ))
    });
    let file = path.to_string_lossy();
    match compiler.compile_into_spirv(
        source,
        shaderc::ShaderKind::Compute,
        &file,
        "main",
        Some(&opts),
    ) {
        Ok(artifact) => artifact.as_binary().to_vec(),
        // shaderc's message already reads "file:line: error: ...".
        Err(e) => fail(format!("GLSL compile error:\n{e}")),
    }
}

fn reflect(name: &str, words: &[u32]) -> Reflection {
    Reflection::new_from_spirv(bytemuck_bytes(words))
        .unwrap_or_else(|e| fail(format!("{name}: SPIR-V reflection failed: {e:?}")))
}

fn bytemuck_bytes(words: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and any byte view of it is valid.
    unsafe { std::slice::from_raw_parts(words.as_ptr().cast::<u8>(), words.len() * 4) }
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let glsl = root.join("glsl");
    let common = glsl.join("common");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-changed=glsl");

    let mut shaders = Vec::new();
    find_shaders(&glsl, &mut shaders);
    let compiler = shaderc::Compiler::new()
        .unwrap_or_else(|e| fail(format!("shaderc: cannot create compiler: {e}")));

    let mut kernels = Vec::new();
    for path in &shaders {
        let rel = path.strip_prefix(&glsl).unwrap().with_extension("");
        let name = rel.to_string_lossy().replace('\\', "/");
        let source =
            fs::read_to_string(path).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
        let optimized = compile(&compiler, path, &source, &common, true);
        // The optimizer may drop debug names: take names from an unoptimized build, the
        // layout from the optimized one (unused bindings may vanish there).
        let plain = compile(&compiler, path, &source, &common, false);

        let refl = reflect(&name, &optimized);
        let names_refl = reflect(&name, &plain);
        let sets = refl
            .get_descriptor_sets()
            .unwrap_or_else(|e| fail(format!("{name}: {e:?}")));
        let named = names_refl
            .get_descriptor_sets()
            .unwrap_or_else(|e| fail(format!("{name}: {e:?}")));
        let mut bindings = Vec::new();
        for (set, set_bindings) in &sets {
            if *set != 0 {
                fail(format!(
                    "{name}: only descriptor set 0 is supported (found set {set})"
                ));
            }
            for (binding, info) in set_bindings {
                if info.binding_count != BindingCount::One {
                    fail(format!(
                        "{name}: binding {binding} is an array; use one buffer per binding"
                    ));
                }
                let uniform = match info.ty {
                    DescriptorType::STORAGE_BUFFER => false,
                    DescriptorType::UNIFORM_BUFFER => true,
                    other => fail(format!(
                        "{name}: binding {binding} has unsupported type {other:?}"
                    )),
                };
                let bname = named
                    .get(set)
                    .and_then(|s| s.get(binding))
                    .map(|i| i.name.clone())
                    .filter(|n| !n.is_empty())
                    .unwrap_or_else(|| format!("binding{binding}"));
                bindings.push((*binding, bname, uniform));
            }
        }
        let push_constant_size = refl
            .get_push_constant_range()
            .unwrap_or_else(|e| fail(format!("{name}: {e:?}")))
            .map(|p| p.offset + p.size)
            .unwrap_or(0);
        if push_constant_size > 128 {
            fail(format!(
                "{name}: push constants are {push_constant_size} bytes; 128 is the portable limit"
            ));
        }
        let workgroup_size = refl.get_compute_group_size().unwrap_or_else(|| {
            fail(format!(
                "{name}: no fixed local_size (specialized sizes are not supported)"
            ))
        });

        let spv_file = out_dir.join(format!("{}.spv", name.replace('/', "__")));
        fs::write(&spv_file, bytemuck_bytes(&optimized)).unwrap();
        kernels.push(Kernel {
            name,
            spv_file,
            bindings,
            push_constant_size,
            workgroup_size,
        });
    }

    let mut src = String::new();
    src.push_str("// Generated by build.rs from glsl/**/*.comp. Do not edit.\n");
    src.push_str("pub static KERNELS: &[KernelInfo] = &[\n");
    let mut ids = BTreeMap::new();
    for (i, k) in kernels.iter().enumerate() {
        let binds: String = k
            .bindings
            .iter()
            .map(|(b, n, u)| format!("BindingInfo {{ binding: {b}, name: {n:?}, uniform: {u} }}, "))
            .collect();
        let (x, y, z) = k.workgroup_size;
        writeln!(
            src,
            "    KernelInfo {{ name: {:?}, spirv: include_bytes!({:?}), bindings: &[{binds}], push_constant_size: {}, workgroup_size: [{x}, {y}, {z}] }},",
            k.name,
            k.spv_file.to_string_lossy(),
            k.push_constant_size
        )
        .unwrap();
        ids.insert(k.name.replace(['/', '-'], "_").to_uppercase(), i);
    }
    src.push_str("];\n\n/// One constant per kernel, named after its path under glsl/.\npub mod ids {\n    #[allow(unused_imports)]
    use super::KernelId;\n");
    for (id, i) in &ids {
        writeln!(src, "    pub const {id}: KernelId = KernelId({i});").unwrap();
    }
    src.push_str("}\n");
    fs::write(out_dir.join("kernel_table.rs"), src).unwrap();
}
