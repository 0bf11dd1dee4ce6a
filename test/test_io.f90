!> Tests of the HDF5 model file (round trip, atomic write, bad files, the shell specification
!> and the 64-bit seed) and of the VRML writer's two layouts. The namelist configuration is tested
!> in test_config; VTK's reading of the VRML in post/tests/test_export.py.
module test_io
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_rotation, only: rotation_about_axis
   use anm_io_model, only: model_type, write_model, read_model
   use anm_io_vrml, only: vrml_mesh_type, write_vrml, vrml_layout
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_io

   character(len=*), parameter :: tmpdir = "build/test-tmp"

contains

   !> Tests of this suite.
   subroutine collect_io(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("model file round trip", test_model_round_trip), &
              new_unittest("model file errors name the file", test_model_errors), &
              new_unittest("VRML layouts: instanced and flat, leading zeros", test_vrml_layouts)]
   end subroutine collect_io

   subroutine write_text(name, text)
      character(len=*), intent(in) :: name, text
      integer :: unit
      call execute_command_line("mkdir -p "//tmpdir)
      open (newunit=unit, file=tmpdir//"/"//name, status="replace", action="write")
      write (unit, '(a)') text
      close (unit)
   end subroutine write_text

   subroutine test_model_round_trip(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: m, r
      logical :: tmp_left
      m%box = [10.0_wp, 11.0_wp, 12.0_wp]
      m%periodic = .false.
      allocate (m%shapes(2), m%shape_names(2))
      m%shapes(1) = sphere_shape(1.0_wp)
      m%shapes(2) = ellipsoid_shape(2.0_wp, 1.5_wp, 1.0_wp, 6)
      m%shape_names = [character(len=256) :: "sphere", "ellipsoid"]
      m%np = 3
      m%shape = [1, 2, 2]
      m%nmax = [0, 6, 4]
      m%sieve = [1, 1, 2]
      m%center = reshape([1.0_wp, 2.0_wp, 3.0_wp, 4.0_wp, 5.0_wp, 6.0_wp, 7.0_wp, 8.0_wp, 9.0_wp], [3, 3])
      allocate (m%rotation(3, 3, 3))
      m%rotation(:, :, 1) = rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], 0.3_wp)
      m%rotation(:, :, 2) = rotation_about_axis([1.0_wp, 0.0_wp, 0.0_wp], 1.3_wp)
      m%rotation(:, :, 3) = rotation_about_axis([1.0_wp, 1.0_wp, 0.0_wp], 2.3_wp)
      m%scale = [1.0_wp, 2.0_wp, 0.5_wp]
      allocate (m%shell_thickness(1, 3))
      m%shell_thickness = 0.1_wp
      m%min_width = [4.0_wp, 1.0_wp]
      m%max_width = [5.0_wp, 2.0_wp]
      m%target_fraction = [0.2_wp, 0.1_wp]
      m%achieved_fraction = [0.19_wp, 0.1_wp]
      m%count = [2, 1]
      m%namelist = "&box length = 10, 11, 12 /"
      m%seed = 5000000000_i8
      m%layer_thickness = [0.01_wp]
      m%layer_colour = reshape([0.1_wp, 0.2_wp, 0.3_wp], [3, 1])
      m%layer_unit = "fraction"
      m%layer_mode = "overlap"
      m%version = "test"
      call execute_command_line("mkdir -p "//tmpdir)
      call write_model(tmpdir//"/round.h5", m, error)
      if (allocated(error)) return
      inquire (file=tmpdir//"/round.h5.tmp", exist=tmp_left)
      call check(error, .not. tmp_left, "temporary file left behind")
      if (allocated(error)) return
      call read_model(tmpdir//"/round.h5", r, error)
      if (allocated(error)) return
      call check(error, r%np == 3 .and. .not. r%periodic .and. all(r%box == m%box), "box and count")
      if (allocated(error)) return
      call check(error, all(r%shape == m%shape) .and. all(r%sieve == m%sieve) .and. all(r%nmax == m%nmax), "indices")
      if (allocated(error)) return
      call check(error, maxval(abs(r%rotation - m%rotation)) + maxval(abs(r%center - m%center)), 0.0_wp, "poses", &
                 thr=0.0_wp)
      if (allocated(error)) return
      call check(error, maxval(abs(r%shapes(2)%a - m%shapes(2)%a)), 0.0_wp, "coefficients", thr=1.0e-15_wp)
      if (allocated(error)) return
      call check(error, trim(r%shape_names(2)) == "ellipsoid" .and. r%namelist == m%namelist, "strings")
      if (allocated(error)) return
      call check(error, allocated(r%layer_unit), "/shells read back")
      if (allocated(error)) return
      call check(error, r%layer_unit == "fraction" .and. r%layer_mode == "overlap" .and. size(r%layer_thickness) == 1 &
                 .and. all(r%layer_colour == m%layer_colour) .and. all(r%layer_thickness == m%layer_thickness), &
                 "shell specification round trip")
   end subroutine test_model_round_trip

   subroutine test_model_errors(error)
      type(error_type), allocatable, intent(out) :: error
      type(model_type) :: r
      type(error_type), allocatable :: err
      call read_model(tmpdir//"/absent.h5", r, err)
      call check(error, allocated(err), "missing file accepted")
      if (allocated(error)) return
      call check(error, index(err%message, "absent.h5") > 0, "names the file: "//err%message)
      if (allocated(error)) return
      call write_text("not-hdf5.h5", "plain text")
      call read_model(tmpdir//"/not-hdf5.h5", r, err)
      call check(error, allocated(err), "text file accepted as model")
      if (allocated(error)) return
      call check(error, index(err%message, "not-hdf5.h5") > 0, "names the file: "//err%message)
   end subroutine test_model_errors

   !> Both layouts of a small scene (two spheres and a translucent ellipsoid): the instanced file
   !> DEFs each mesh once and USEs it again, the flat one has one Shape per look and no Transform;
   !> every number has a leading zero (VTK reads '.55' as 0); the flat vertices are the instanced
   !> body vertices moved to the world (checked on the first vertex).
   subroutine test_vrml_layouts(error)
      type(error_type), allocatable, intent(out) :: error
      type(vrml_mesh_type) :: meshes(2)
      real(wp) :: center(3, 3), rotation(3, 3, 3), scale(3), body(3), world(3), first(3)
      character(len=:), allocatable :: inst, flat
      integer :: k
      meshes(1) = vrml_mesh_type(sphere_shape(1.0_wp), 4, [0.55_wp, 0.45_wp, 0.35_wp], 0.0_wp)
      meshes(2) = vrml_mesh_type(ellipsoid_shape(2.0_wp, 1.5_wp, 1.0_wp, 6), 6, [0.25_wp, 0.5_wp, 0.75_wp], 0.6_wp)
      center = reshape([2.0_wp, 2.0_wp, 2.0_wp, 5.0_wp, 1.0_wp, 3.0_wp, 7.0_wp, 6.0_wp, 5.0_wp], [3, 3])
      rotation(:, :, 1) = rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], 0.3_wp)
      rotation(:, :, 2) = rotation_about_axis([1.0_wp, 0.0_wp, 0.0_wp], 1.3_wp)
      rotation(:, :, 3) = rotation_about_axis([1.0_wp, 1.0_wp, 0.0_wp], 2.3_wp)
      scale = [0.5_wp, 0.25_wp, 0.4_wp]
      call execute_command_line("mkdir -p "//tmpdir)
      call write_vrml(tmpdir//"/inst.wrl", [10.0_wp, 10.0_wp, 10.0_wp], meshes, [1, 1, 2], center, rotation, scale, &
                      error)
      if (allocated(error)) return
      call write_vrml(tmpdir//"/flat.wrl", [10.0_wp, 10.0_wp, 10.0_wp], meshes, [1, 1, 2], center, rotation, scale, &
                      error, layout=vrml_layout%flat)
      if (allocated(error)) return
      inst = read_text(tmpdir//"/inst.wrl")
      flat = read_text(tmpdir//"/flat.wrl")
      call check(error, count_of(inst, "Transform {") == 3 .and. count_of(inst, "DEF M") == 2 &
                 .and. count_of(inst, "USE M1") == 1, "instanced: 3 Transforms, 2 DEFs, 1 USE")
      if (allocated(error)) return
      call check(error, count_of(flat, "Transform") == 0 .and. count_of(flat, "Shape {") == 3 &
                 .and. count_of(flat, "# 2 surfaces") == 1 .and. count_of(flat, "# 1 surfaces") == 1, &
                 "flat: box and one Shape per look, no Transform")
      if (allocated(error)) return
      call check_looks(error, inst)
      if (allocated(error)) return
      call check_looks(error, flat)
      if (allocated(error)) return
      ! first vertex: the first ring's first point of mesh 1 (theta = pi/4, phi = 0)
      body = [sin(0.25_wp * acos(-1.0_wp)), 0.0_wp, cos(0.25_wp * acos(-1.0_wp))]
      world = center(:, 1) + scale(1) * matmul(rotation(:, :, 1), body)
      k = index(flat, "# 2 surfaces")
      k = k + index(flat(k:), "point [")
      k = k + index(flat(k:), new_line("a"))
      read (flat(k:k + index(flat(k:), ",") - 2), *) first
      call check(error, maxval(abs(first - world)) < 1.0e-4_wp, "flat: first vertex in world coordinates")
   end subroutine test_vrml_layouts

   !> Colours and transparency with leading zeros, and no number without its leading zero.
   subroutine check_looks(error, text)
      type(error_type), allocatable, intent(out) :: error
      character(len=*), intent(in) :: text
      call check(error, index(text, "diffuseColor 0.5500 0.4500 0.3500 transparency 0.000") > 0 &
                 .and. index(text, "diffuseColor 0.2500 0.5000 0.7500 transparency 0.600") > 0, &
                 "colours and transparency with leading zeros")
      if (allocated(error)) return
      call check(error, index(text, " .") == 0 .and. index(text, "-.") == 0 .and. index(text, "[.") == 0, &
                 "a number without its leading zero")
   end subroutine check_looks

   pure integer function count_of(text, word) result(n)
      character(len=*), intent(in) :: text, word
      integer :: i, k
      n = 0
      i = 1
      do
         k = index(text(i:), word)
         if (k == 0) exit
         n = n + 1
         i = i + k - 1 + len(word)
      end do
   end function count_of

   function read_text(path) result(text)
      character(len=*), intent(in) :: path
      character(len=:), allocatable :: text
      integer :: unit, n
      open (newunit=unit, file=path, access="stream", form="unformatted", action="read")
      inquire (unit=unit, size=n)
      allocate (character(len=n) :: text)
      read (unit) text
      close (unit)
   end function read_text
end module test_io
