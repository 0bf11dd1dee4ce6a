!> The one table of the model file's groups and datasets with their units and descriptions: the
!> writer (anm_io_model) stores each row as the attributes `units` and `description` of its object,
!> and docs/model-file.md lists the same rows (post/tests/test_model_schema.py checks that the
!> file and the document agree, so neither can drift).
!>
!> Units: "mm"; "1" for dimensionless numbers (fractions, ratios, indices, counts); "shape unit"
!> for coefficients in the shape's own frame; "s" for seconds; "-" for groups and text.
!>
!> Usage:
!>     do k = 1, size(model_schema)
!>        print *, trim(model_schema(k)%path), trim(model_schema(k)%units)
!>     end do
module anm_io_model_schema
   implicit none
   private

   public :: schema_entry_type, model_schema

   !> One group or dataset of the model file.
   type :: schema_entry_type
      !> HDF5 path.
      character(len=40) :: path = ""
      !> Units (see the module doc).
      character(len=24) :: units = ""
      !> What it holds.
      character(len=160) :: description = ""
   end type schema_entry_type

   !> Every group and dataset the writer may write (optional ones are written only when present).
   type(schema_entry_type), parameter :: model_schema(*) = [ &
      schema_entry_type("/", "-", "an Anm model file (docs/model-file.md)"), &
      schema_entry_type("/box", "-", "the box"), &
      schema_entry_type("/box/length", "mm", "box edges along x, y, z"), &
      schema_entry_type("/shapes", "-", "the particle shapes"), &
      schema_entry_type("/shapes/coeffs", "shape unit", &
                        "Re, Im of a_nm in NIST line order (n = 0.., m = n..-n), zero-padded to the largest degree"), &
      schema_entry_type("/shapes/nmax", "1", "highest degree stored for each shape"), &
      schema_entry_type("/shapes/name", "-", "source file name or generator tag of each shape"), &
      schema_entry_type("/particles", "-", "the placed particles"), &
      schema_entry_type("/particles/shape", "1", "0-based index into /shapes"), &
      schema_entry_type("/particles/center", "mm", "centre, inside the box"), &
      schema_entry_type("/particles/rotation", "1", "rotation body->world: world = R @ body"), &
      schema_entry_type("/particles/scale", "mm", "mm per shape unit"), &
      schema_entry_type("/particles/nmax", "1", "expansion order used for the particle"), &
      schema_entry_type("/particles/sieve", "1", "0-based sieve index"), &
      schema_entry_type("/particles/shell_thickness", "mm", &
                        "cumulative outer distance of each shell layer from the surface (absent without shells)"), &
      schema_entry_type("/sieves", "-", "the sieves (grading)"), &
      schema_entry_type("/sieves/min_width", "mm", "smallest sieve width of the sieve"), &
      schema_entry_type("/sieves/max_width", "mm", "largest sieve width of the sieve"), &
      schema_entry_type("/sieves/target_fraction", "1", "prescribed volume fraction of the box"), &
      schema_entry_type("/sieves/achieved_fraction", "1", "achieved volume fraction of the box"), &
      schema_entry_type("/sieves/count", "1", "particles per sieve"), &
      schema_entry_type("/sieves/shell_fraction", "1", &
                        "shell volume of the sieve's particles (outermost layer minus particle) over the box volume"), &
      schema_entry_type("/shells", "-", "the shell specification of the run (the &shells group resolved)"), &
      schema_entry_type("/shells/thickness", "see /shells unit", &
                        "cumulative thickness of each layer, in the group's unit (mm, or a fraction of L)"), &
      schema_entry_type("/shells/colour", "1", "RGB (0..1) of each layer"), &
      schema_entry_type("/run", "-", "how the model was made"), &
      schema_entry_type("/run/namelist", "-", "the input namelist text as read"), &
      schema_entry_type("/run/resolved_namelist", "-", "every setting with its default, as the run used it")]
end module anm_io_model_schema
