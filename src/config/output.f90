!> The `&output` group: where the model and its companions are written (docs/user-guide.md).
!>
!>     &output directory = 'out', name = 'default', vrml = .true. /
!>
!> Validates: name non-empty without '/'; directory non-empty; tessellation per sieve -1
!> (default: finer for larger sieves) or 4..400, none listed beyond nsieve; vrml_layout
!> 'instanced' or 'flat' (resolved to `vrml_layout%...`).
!>
!> Usage:
!>     call load_output_config(output, nml, nsieve, error)
module anm_config_output
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string, to_lower
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, max_line
   use anm_config_format, only: logical_text, quoted
   use anm_config_sieves, only: max_sieves
   use anm_io_vrml, only: vrml_layout, vrml_layout_name
   implicit none
   private

   public :: output_config_type, load_output_config, dump_output_config, default_tessellation, vrml_layout, &
      & vrml_layout_name

   !> The outputs.
   type :: output_config_type
      !> Output folder.
      character(len=512) :: directory = "out"
      !> Model name (files NAME.h5, NAME-summary.csv, NAME.wrl).
      character(len=128) :: name = "model"
      !> VRML output and one VRML file per layer.
      logical :: vrml = .true., vrml_per_layer = .false.
      !> VRML tessellation (polar divisions) per sieve.
      integer, allocatable :: tessellation(:)
      !> Overwrite existing outputs (otherwise `anm run` refuses, naming the file; `--force`).
      logical :: overwrite = .false.
      !> VRML file layout, one of `vrml_layout` (instanced: small; flat: linear import in VTK).
      integer :: vrml_layout = vrml_layout%instanced
   end type output_config_type

contains

   !> Read and validate `&output` (optional: defaults).
   subroutine load_output_config(self, nml, nsieve, error)
      !> The outputs.
      type(output_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Number of sieves (validated).
      integer, intent(in) :: nsieve
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      character(len=512) :: directory
      character(len=128) :: name
      logical :: vrml, vrml_per_layer, overwrite
      integer :: tessellation(max_sieves)
      character(len=32) :: vrml_layout
      namelist /output/ directory, name, vrml, vrml_per_layer, tessellation, overwrite, vrml_layout
      integer :: ig, stat, i
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      directory = self%directory
      name = self%name
      vrml = self%vrml
      vrml_per_layer = self%vrml_per_layer
      overwrite = self%overwrite
      tessellation = -1
      vrml_layout = vrml_layout_name(self%vrml_layout)
      ig = find_group(nml, "output")
      if (ig > 0) then
         lines = nml%groups(ig)%lines
         read (lines, nml=output, iostat=stat, iomsg=msg)
         if (stat /= 0) then
            call group_read_error(error, nml, ig, msg, reader)
            return
         end if
      end if
      if (len_trim(name) == 0 .or. index(name, "/") > 0) then
         call config_error(error, nml, ig, "output", "name", "= '"//trim(name)//"' must be a non-empty file name without '/'")
         return
      end if
      if (len_trim(directory) == 0) then
         call config_error(error, nml, ig, "output", "directory", "is empty (use '.' for the current folder)")
         return
      end if
      if (any(tessellation(nsieve + 1:) /= -1)) then
         call config_error(error, nml, ig, "output", "tessellation", "lists more values than nsieve = "//to_string(nsieve))
         return
      end if
      allocate (self%tessellation(nsieve))
      do i = 1, nsieve
         if (tessellation(i) == -1) then
            self%tessellation(i) = default_tessellation(i, nsieve)
         else if (tessellation(i) < 4 .or. tessellation(i) > 400) then
            call config_error(error, nml, ig, "output", "tessellation("//to_string(i)//")", "= " &
                              //to_string(tessellation(i))//" must be in 4..400")
            return
         else
            self%tessellation(i) = tessellation(i)
         end if
      end do
      select case (to_lower(trim(vrml_layout)))
      case ("instanced")
         self%vrml_layout = layout_instanced()
      case ("flat")
         self%vrml_layout = layout_flat()
      case default
         call config_error(error, nml, ig, "output", "vrml_layout", "= '"//trim(vrml_layout) &
                           //"' must be 'instanced' or 'flat'")
         return
      end select
      self%directory = directory
      self%name = name
      self%vrml = vrml
      self%vrml_per_layer = vrml_per_layer
      self%overwrite = overwrite

   contains

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=output, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_output_config

   ! the local namelist variable vrml_layout shadows the enumerator inside load_output_config
   pure integer function layout_instanced() result(k)
      k = vrml_layout%instanced
   end function layout_instanced

   pure integer function layout_flat() result(k)
      k = vrml_layout%flat
   end function layout_flat

   !> Default VRML tessellation: finer for the first (largest) sieves.
   pure function default_tessellation(i, n) result(t)
      !> Sieve and number of sieves.
      integer, intent(in) :: i, n
      integer :: t
      t = max(8, 32 - (24 * (i - 1)) / max(1, n))
   end function default_tessellation

   !> The resolved `&output` group as namelist text.
   pure function dump_output_config(self) result(text)
      !> The outputs.
      type(output_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      integer :: i
      text = "&output directory = "//quoted(trim(self%directory))//", name = "//quoted(trim(self%name)) &
             //", vrml = "//logical_text(self%vrml)//", vrml_per_layer = "//logical_text(self%vrml_per_layer) &
             //", overwrite = "//logical_text(self%overwrite)
      do i = 1, size(self%tessellation)
         text = text//", tessellation("//to_string(i)//") = "//to_string(self%tessellation(i))
      end do
      text = text//", vrml_layout = "//quoted(vrml_layout_name(self%vrml_layout))//" /"//new_line("a")
   end function dump_output_config
end module anm_config_output
