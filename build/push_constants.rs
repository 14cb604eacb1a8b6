//! Reads a kernel's push-constant block from its SPIR-V (member names, types, offsets) and
//! writes the `#[repr(C)]` Rust struct that mirrors it field for field, so host code fills
//! named fields instead of positional vectors explained by comments.

use rspirv::dr::{Module, Operand};
use rspirv::spirv::{Decoration, Op, StorageClass};

/// One member of a push-constant block.
#[derive(Clone, Debug, PartialEq)]
pub struct Member {
    pub name: String,
    /// Rust type: "u32", "[f32; 4]", "[[f32; 4]; 3]", ...
    pub rust_type: String,
    pub offset: u32,
    pub size: u32,
}

/// A push-constant block: the GLSL block's type name and its members in offset order.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub name: String,
    pub members: Vec<Member>,
}

fn name_of(module: &Module, id: u32) -> Option<String> {
    module
        .debug_names
        .iter()
        .find_map(|i| match (i.class.opcode, &i.operands[..]) {
            (Op::Name, [Operand::IdRef(t), Operand::LiteralString(s)]) if *t == id => {
                Some(s.clone())
            }
            _ => None,
        })
}

fn member_name(module: &Module, ty: u32, index: u32) -> Option<String> {
    module
        .debug_names
        .iter()
        .find_map(|i| match (i.class.opcode, &i.operands[..]) {
            (
                Op::MemberName,
                [Operand::IdRef(t), Operand::LiteralBit32(m), Operand::LiteralString(s)],
            ) if *t == ty && *m == index => Some(s.clone()),
            _ => None,
        })
}

fn member_offset(module: &Module, ty: u32, index: u32) -> Option<u32> {
    module.annotations.iter().find_map(|i| match (i.class.opcode, &i.operands[..]) {
        (
            Op::MemberDecorate,
            [Operand::IdRef(t), Operand::LiteralBit32(m), Operand::Decoration(Decoration::Offset), Operand::LiteralBit32(o)],
        ) if *t == ty && *m == index => Some(*o),
        _ => None,
    })
}

fn type_inst(module: &Module, id: u32) -> Option<&rspirv::dr::Instruction> {
    module
        .types_global_values
        .iter()
        .find(|i| i.result_id == Some(id))
}

/// The Rust type and byte size of a scalar, vector or array of them.
fn rust_type(module: &Module, id: u32) -> Result<(String, u32), String> {
    let inst = type_inst(module, id).ok_or("unknown type id")?;
    match (inst.class.opcode, &inst.operands[..]) {
        (Op::TypeInt, [Operand::LiteralBit32(32), Operand::LiteralBit32(signed)]) => {
            Ok((if *signed == 1 { "i32" } else { "u32" }.into(), 4))
        }
        (Op::TypeFloat, [Operand::LiteralBit32(32)]) => Ok(("f32".into(), 4)),
        (Op::TypeVector, [Operand::IdRef(c), Operand::LiteralBit32(n)]) => {
            let (t, s) = rust_type(module, *c)?;
            Ok((format!("[{t}; {n}]"), s * n))
        }
        (Op::TypeArray, [Operand::IdRef(elem), Operand::IdRef(len)]) => {
            let (t, s) = rust_type(module, *elem)?;
            let n = match type_inst(module, *len).map(|i| &i.operands[..]) {
                Some([Operand::LiteralBit32(n)]) => *n,
                _ => return Err("array length is not a constant".into()),
            };
            let stride = module.annotations.iter().find_map(|i| match &i.operands[..] {
                [Operand::IdRef(t), Operand::Decoration(Decoration::ArrayStride), Operand::LiteralBit32(s)]
                    if *t == inst.result_id.unwrap() => Some(*s),
                _ => None,
            });
            if stride != Some(s) {
                return Err(format!(
                    "array stride {stride:?} differs from its element size {s}"
                ));
            }
            Ok((format!("[{t}; {n}]"), s * n))
        }
        _ => Err(format!(
            "unsupported member type {:?} (use 32-bit scalars, vectors, arrays)",
            inst.class.opcode
        )),
    }
}

/// The push-constant block of `module` (compiled with debug names), if it has one.
pub fn read_block(module: &Module) -> Result<Option<Block>, String> {
    let var = module.types_global_values.iter().find(|i| {
        i.class.opcode == Op::Variable
            && matches!(
                i.operands.first(),
                Some(Operand::StorageClass(StorageClass::PushConstant))
            )
    });
    let Some(var) = var else { return Ok(None) };
    let ptr = type_inst(module, var.result_type.ok_or("variable without type")?)
        .ok_or("no pointer type")?;
    let Some(Operand::IdRef(struct_id)) = ptr.operands.get(1) else {
        return Err("push-constant pointer without a pointee".into());
    };
    let st = type_inst(module, *struct_id).ok_or("no block type")?;
    let name = name_of(module, *struct_id).ok_or("push-constant block without a type name")?;
    let mut members = Vec::new();
    for (index, op) in st.operands.iter().enumerate() {
        let Operand::IdRef(ty) = op else {
            return Err("malformed block".into());
        };
        let index = index as u32;
        let (rust_type, size) = rust_type(module, *ty).map_err(|e| format!("{name}: {e}"))?;
        members.push(Member {
            name: member_name(module, *struct_id, index).ok_or("member without a name")?,
            rust_type,
            offset: member_offset(module, *struct_id, index).ok_or("member without an offset")?,
            size,
        });
    }
    members.sort_by_key(|m| m.offset);
    // Rust's repr(C) places 4-byte-aligned fields back to back: the block must too.
    let mut end = 0;
    for m in &members {
        if m.offset != end {
            return Err(format!(
                "{name}.{}: at byte {} after a gap from byte {end}; order the members so the \
                 block has no padding (the Rust struct mirrors it field for field)",
                m.name, m.offset
            ));
        }
        end += m.size;
    }
    Ok(Some(Block { name, members }))
}

/// Size in bytes of the block's members.
pub fn block_size(block: &Block) -> u32 {
    block.members.iter().map(|m| m.size).sum()
}

/// The Rust struct mirroring `block`.
pub fn rust_struct(block: &Block, kernels: &[String]) -> String {
    let mut s = format!(
        "/// Push constants of `{}` (generated from the GLSL block `{}`).\n\
         #[repr(C)]\n#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]\n\
         pub struct {} {{\n",
        kernels.join("`, `"),
        block.name,
        block.name
    );
    for m in &block.members {
        s += &format!("    pub {}: {},\n", m.name, m.rust_type);
    }
    s + "}\n"
}
