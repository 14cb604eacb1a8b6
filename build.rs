//! Compiles every `glsl/**/*.comp` to SPIR-V 1.5 (Vulkan 1.2) with shaderc, reflects each
//! module with rspirv-reflect, and writes `$OUT_DIR/kernel_table.rs`: one entry per kernel
//! with its SPIR-V, bindings, push-constant size and workgroup size, and one typed id per
//! kernel naming its push-constant struct. The host builds every descriptor layout from
//! this table; none is written by hand.
//!
//! It also writes the GLSL/Rust contract: the shared constants of
//! glsl/common/shared_constants.txt as a GLSL include and Rust constants, and one Rust
//! struct per push-constant block read from the SPIR-V (`$OUT_DIR/contract.rs`).

#[path = "build/push_constants.rs"]
mod push_constants;
#[path = "build/shared_constants.rs"]
mod shared_constants;

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
    /// The push-constant block, read from the SPIR-V.
    params: Option<push_constants::Block>,
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
    include_dirs: &[PathBuf],
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
    let include_dirs = include_dirs.to_vec();
    opts.set_include_callback(move |name, kind, requester, _depth| {
        let local = Path::new(requester).parent().map(|d| d.join(name));
        let shared = include_dirs.iter().map(|d| d.join(name));
        let candidates: Vec<PathBuf> = match kind {
            shaderc::IncludeType::Relative => local.into_iter().chain(shared).collect(),
            shaderc::IncludeType::Standard => shared.collect(),
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
            "include \"{name}\" not found (looked beside {requester}, in glsl/common/ and the generated includes)"
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

/// The descriptor bindings of set 0: (binding, GLSL instance name, is_uniform).
fn bindings_of(name: &str, optimized: &Reflection, plain: &Reflection) -> Vec<(u32, String, bool)> {
    let sets = optimized
        .get_descriptor_sets()
        .unwrap_or_else(|e| fail(format!("{name}: {e:?}")));
    let named = plain
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
            // The optimizer may drop debug names: names come from the unoptimized build.
            let bname = named
                .get(set)
                .and_then(|s| s.get(binding))
                .map(|i| i.name.clone())
                .filter(|n| !n.is_empty())
                .unwrap_or_else(|| format!("binding{binding}"));
            bindings.push((*binding, bname, uniform));
        }
    }
    bindings
}

/// Compiles and reflects one kernel; writes its SPIR-V next to the table.
fn build_kernel(
    compiler: &shaderc::Compiler,
    glsl: &Path,
    path: &Path,
    include_dirs: &[PathBuf],
    out_dir: &Path,
) -> Kernel {
    let rel = path.strip_prefix(glsl).unwrap().with_extension("");
    let name = rel.to_string_lossy().replace('\\', "/");
    let source =
        fs::read_to_string(path).unwrap_or_else(|e| fail(format!("{}: {e}", path.display())));
    let optimized = compile(compiler, path, &source, include_dirs, true);
    // The optimizer may drop debug names: take names from an unoptimized build, the
    // layout from the optimized one (unused bindings may vanish there).
    let plain = compile(compiler, path, &source, include_dirs, false);
    let refl = reflect(&name, &optimized);
    let bindings = bindings_of(&name, &refl, &reflect(&name, &plain));
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
    let module = rspirv::dr::load_words(&plain)
        .unwrap_or_else(|e| fail(format!("{name}: SPIR-V parse failed: {e}")));
    let params = push_constants::read_block(&module)
        .unwrap_or_else(|e| fail(format!("{name}: push constants: {e}")));
    let params_size = params.as_ref().map_or(0, push_constants::block_size);
    if params_size != push_constant_size {
        fail(format!(
            "{name}: push-constant members take {params_size} bytes, the block {push_constant_size}"
        ));
    }
    let workgroup_size = refl.get_compute_group_size().unwrap_or_else(|| {
        fail(format!(
            "{name}: no fixed local_size (specialized sizes are not supported)"
        ))
    });
    let spv_file = out_dir.join(format!("{}.spv", name.replace('/', "__")));
    fs::write(&spv_file, bytemuck_bytes(&optimized)).unwrap();
    Kernel {
        name,
        spv_file,
        bindings,
        push_constant_size,
        workgroup_size,
        params,
    }
}

/// The Rust name of a kernel's push-constant type: its block's name, or `()` without one.
fn params_type(k: &Kernel) -> String {
    k.params.as_ref().map_or("()".into(), |b| {
        format!("crate::contract::params::{}", b.name)
    })
}

/// `$OUT_DIR/kernel_table.rs`: the reflected table and one typed id per kernel.
fn kernel_table(kernels: &[Kernel]) -> String {
    let mut src = String::new();
    src.push_str("// Generated by build.rs from glsl/**/*.comp. Do not edit.\n");
    src.push_str("pub static KERNELS: &[KernelInfo] = &[\n");
    for k in kernels {
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
    }
    src.push_str("];\n\n/// One constant per kernel, named after its path under glsl/ and typed by its push constants.\npub mod ids {\n    #[allow(unused_imports)]\n    use super::{Kernel, KernelId};\n");
    let mut ids = BTreeMap::new();
    for (i, k) in kernels.iter().enumerate() {
        ids.insert(
            k.name.replace(['/', '-'], "_").to_uppercase(),
            (i, params_type(k)),
        );
    }
    for (id, (i, ty)) in &ids {
        writeln!(
            src,
            "    pub const {id}: Kernel<{ty}> = Kernel::new(KernelId({i}));"
        )
        .unwrap();
    }
    src + "}\n"
}

/// `$OUT_DIR/contract.rs`: the shared constants and one struct per push-constant block;
/// kernels that share a block (through a common include) share its struct.
fn contract(constants: &[shared_constants::Constant], kernels: &[Kernel]) -> String {
    let mut blocks: BTreeMap<String, (&push_constants::Block, Vec<String>)> = BTreeMap::new();
    for k in kernels {
        let Some(block) = &k.params else { continue };
        let entry = blocks
            .entry(block.name.clone())
            .or_insert_with(|| (block, Vec::new()));
        if entry.0 != block {
            fail(format!(
                "push-constant block {} differs between {} and {}: give each layout its own name",
                block.name, entry.1[0], k.name
            ));
        }
        entry.1.push(k.name.clone());
    }
    let mut src = shared_constants::rust(constants);
    src.push_str(
        "\n/// Push-constant structs, one per GLSL push-constant block.\npub mod params {\n",
    );
    for (block, users) in blocks.values() {
        src += &push_constants::rust_struct(block, users);
    }
    src + "}\n"
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let glsl = root.join("glsl");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    println!("cargo:rerun-if-changed=glsl");

    let constants_file = glsl.join("common/shared_constants.txt");
    let text = fs::read_to_string(&constants_file)
        .unwrap_or_else(|e| fail(format!("{}: {e}", constants_file.display())));
    let constants = shared_constants::parse(&text)
        .unwrap_or_else(|e| fail(format!("{}: {e}", constants_file.display())));
    let generated_glsl = out_dir.join("glsl");
    fs::create_dir_all(&generated_glsl).unwrap();
    fs::write(
        generated_glsl.join("shared_constants.glsl"),
        shared_constants::glsl(&constants),
    )
    .unwrap();

    let mut shaders = Vec::new();
    find_shaders(&glsl, &mut shaders);
    let compiler = shaderc::Compiler::new()
        .unwrap_or_else(|e| fail(format!("shaderc: cannot create compiler: {e}")));
    let include_dirs = [glsl.join("common"), generated_glsl];
    let kernels: Vec<Kernel> = shaders
        .iter()
        .map(|path| build_kernel(&compiler, &glsl, path, &include_dirs, &out_dir))
        .collect();
    fs::write(out_dir.join("kernel_table.rs"), kernel_table(&kernels)).unwrap();
    fs::write(out_dir.join("contract.rs"), contract(&constants, &kernels)).unwrap();
}
