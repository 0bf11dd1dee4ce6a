!> Parameter studies of the EOB method written as CSV (thesis section 2.5.1): the extent-box
!> volume V_box versus N_ext for one particle (Fig 2.14) and D_overlap versus N_box for two barely
!> overlapping copies of a particle (Fig 2.15).
!>
!> Usage:
!>     call study_next(shape, 14, "vbox.csv", error)
!>     call study_nbox(shape, 14, 2024, "doverlap.csv", error)
module anm_contact_studies
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_output, only: write_text_file
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type
   use anm_geometry_extent, only: extent_scan
   use anm_geometry_rotation, only: random_rotation
   use anm_contact_body, only: contact_body_type, new_contact_body
   use anm_contact_overlap, only: overlap_depth
   implicit none
   private

   public :: study_next, study_nbox

contains

   !> Write `next,v_box` for N_ext = 4..160 (thesis extent scan, shape units cubed).
   subroutine study_next(shape, nused, path, error)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Order used (negative: all coefficients).
      integer, intent(in) :: nused
      !> Output CSV file.
      character(len=*), intent(in) :: path
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body
      integer :: next
      character(len=80) :: line
      character(len=:), allocatable :: text
      real(wp) :: lo(3), hi(3)
      call build(body, shape, nused, error)
      if (allocated(error)) return
      text = "next,v_box,v_box_certified"//new_line("a")
      do next = 4, 160, 2
         call extent_scan(body%shape, next, lo, hi)
         write (line, '(i0,2(",",es16.9))') next, product(hi - lo), product(body%box_hi - body%box_lo)
         text = text//trim(line)//new_line("a")
      end do
      call write_text_file(path, text, error)
   end subroutine study_next

   !> Write `nbox,d_overlap` for N_box = 10..300 for two copies of the particle (random
   !> rotations from `seed`) placed along x at 0.998 times their contact distance (found by
   !> bisection on D_overlap at N_box = 1024); D_overlap in shape units.
   subroutine study_nbox(shape, nused, seed, path, error)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Order used (negative: all coefficients).
      integer, intent(in) :: nused
      !> Seed of the two rotations.
      integer, intent(in) :: seed
      !> Output CSV file.
      character(len=*), intent(in) :: path
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body
      type(rng_type) :: rng
      real(wp) :: rota(3, 3), rotb(3, 3), lo, hi, mid, zero(3), ex(3)
      integer :: nbox, it
      character(len=80) :: line
      character(len=:), allocatable :: text
      call build(body, shape, nused, error)
      if (allocated(error)) return
      call new_rng(rng, int(seed, i8), 1_i8)
      rota = random_rotation(rng)
      rotb = random_rotation(rng)
      zero = 0.0_wp
      ex = [1.0_wp, 0.0_wp, 0.0_wp]
      lo = 2.0_wp * body%r_min
      hi = 2.0_wp * body%r_max
      do it = 1, 40
         mid = 0.5_wp * (lo + hi)
         if (overlap_depth(body, zero, rota, 1.0_wp, body, mid * ex, rotb, 1.0_wp, 1024) > 0.0_wp) then
            lo = mid
         else
            hi = mid
         end if
      end do
      text = "nbox,d_overlap"//new_line("a")
      do nbox = 10, 300, 10
         write (line, '(i0,",",es16.9)') nbox, overlap_depth(body, zero, rota, 1.0_wp, body, 0.998_wp * lo * ex, &
                                                             rotb, 1.0_wp, nbox)
         text = text//trim(line)//new_line("a")
      end do
      call write_text_file(path, text, error)
   end subroutine study_nbox

   subroutine build(body, shape, nused, error)
      type(contact_body_type), intent(out) :: body
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: nused
      type(error_type), allocatable, intent(out) :: error
      if (nused >= 0) then
         call new_contact_body(body, shape, error, nused=nused)
      else
         call new_contact_body(body, shape, error)
      end if
   end subroutine build
end module anm_contact_studies
