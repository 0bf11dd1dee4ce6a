!> Resources checked before allocating: the memory a request needs against what the machine has
!> (`MemAvailable` of /proc/meminfo, or the environment variable ANM_MEMORY_LIMIT, in bytes with
!> an optional K, M, G or T suffix, which tests and batch systems use to set a smaller limit).
!> A request above it is refused with the estimate, the memory available and the variable to
!> change, instead of crashing half-way with an allocation error.
!>
!> Usage:
!>     call check_memory(48.0_wp * n**2, "anm verify --resolution "//to_string(n), "--resolution", error)
module anm_core_resources
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   implicit none
   private

   public :: available_memory, check_memory, format_bytes, run_memory_estimate, particle_count_estimate, &
      & bytes_per_particle, bytes_per_kind, shape_memory

   !> Parking memory per particle: the packing's arrays (128 bytes: centre, rotation, scale,
   !> bounding radius, kind, sieve, record ids), at most one 128-byte cell-list block and the
   !> cell heads; the model takes the packing's arrays, and the output's temporary rotation (72
   !> bytes) comes after the cell list is freed (docs/performance-notes.md, issue 15: 10^7 sand
   !> grains), rounded up.
   real(wp), parameter :: bytes_per_particle = 300.0_wp
   !> Memory of one particle kind (a shape at a sieve: the contact body with its packed boxes and
   !> shells), about 4.5 MB measured at the default n_box, rounded up.
   real(wp), parameter :: bytes_per_kind = 5.0e6_wp
   !> Fixed part of a run (program, HDF5, tables).
   real(wp), parameter :: bytes_base = 64.0e6_wp
   !> Volume of the smallest particle passing a sieve of width w, as a multiple of w**3 (a sphere
   !> is 0.52; flat and elongated aggregate grains about 0.5 to 1.1 on average): the particle count
   !> estimated from it is an upper bound for the usual shapes.
   real(wp), parameter :: volume_factor = 0.5_wp

contains

   !> Memory available to this program in bytes and where the figure comes from; a negative value
   !> when it cannot be known (then nothing is refused).
   subroutine available_memory(bytes, source)
      !> Bytes available.
      real(wp), intent(out) :: bytes
      !> "ANM_MEMORY_LIMIT" or "MemAvailable in /proc/meminfo".
      character(len=:), allocatable, intent(out) :: source
      character(len=64) :: text
      character(len=256) :: line
      integer :: stat, length, unit
      real(wp) :: kb

      bytes = -1.0_wp
      call get_environment_variable("ANM_MEMORY_LIMIT", text, length, stat)
      if (stat == 0 .and. length > 0) then
         source = "ANM_MEMORY_LIMIT"
         bytes = parse_bytes(text)
         if (bytes >= 0.0_wp) return
      end if
      source = "MemAvailable in /proc/meminfo"
      open (newunit=unit, file="/proc/meminfo", status="old", action="read", iostat=stat)
      if (stat /= 0) return
      do
         read (unit, '(a)', iostat=stat) line
         if (stat /= 0) exit
         if (index(line, "MemAvailable:") == 1) then
            read (line(len("MemAvailable:") + 1:), *, iostat=stat) kb
            if (stat == 0) bytes = 1024.0_wp * kb
            exit
         end if
      end do
      close (unit)
   end subroutine available_memory

   !> Bytes of a text like "2000000", "512M", "4G" (binary units); negative when not a size.
   pure function parse_bytes(text) result(bytes)
      character(len=*), intent(in) :: text
      real(wp) :: bytes, mult
      character(len=:), allocatable :: t
      integer :: stat
      t = trim(adjustl(text))
      mult = 1.0_wp
      bytes = -1.0_wp
      if (len(t) == 0) return
      select case (t(len(t):len(t)))
      case ("k", "K")
         mult = 1024.0_wp
      case ("m", "M")
         mult = 1024.0_wp**2
      case ("g", "G")
         mult = 1024.0_wp**3
      case ("t", "T")
         mult = 1024.0_wp**4
      end select
      if (mult > 1.0_wp) t = t(:len(t) - 1)
      if (len(t) == 0 .or. verify(t, "0123456789.eE+") /= 0) return
      read (t, *, iostat=stat) bytes
      if (stat /= 0 .or. .not. (bytes >= 0.0_wp)) then
         bytes = -1.0_wp
      else
         bytes = bytes * mult
      end if
   end function parse_bytes

   !> Bytes as text: "512 MB", "23.5 GB".
   pure function format_bytes(bytes) result(text)
      !> Bytes.
      real(wp), intent(in) :: bytes
      character(len=:), allocatable :: text
      character(len=32) :: buf
      if (bytes >= 1.0e12_wp) then
         write (buf, '(f0.1,a)') bytes / 1.0e12_wp, " TB"
      else if (bytes >= 1.0e9_wp) then
         write (buf, '(f0.1,a)') bytes / 1.0e9_wp, " GB"
      else if (bytes >= 1.0e6_wp) then
         write (buf, '(i0,a)') nint(bytes / 1.0e6_wp), " MB"
      else
         write (buf, '(i0,a)') nint(max(0.0_wp, bytes) / 1.0e3_wp), " kB"
      end if
      text = trim(adjustl(buf))
      if (text(1:1) == ".") text = "0"//text
   end function format_bytes

   !> Refuse a request needing `need` bytes when that is more than the memory available. The
   !> message names the request, the estimate, the memory available and the variable to change.
   subroutine check_memory(need, what, variable, error)
      !> Estimated bytes.
      real(wp), intent(in) :: need
      !> The request, e.g. "&synthetic count = 1000000000".
      character(len=*), intent(in) :: what
      !> The variable or option to reduce.
      character(len=*), intent(in) :: variable
      !> Error when the request does not fit.
      type(error_type), allocatable, intent(out) :: error
      real(wp) :: avail
      character(len=:), allocatable :: source
      call available_memory(avail, source)
      if (avail < 0.0_wp) return
      if (need > avail) then
         call fatal_error(error, what//" needs about "//format_bytes(need)//" of memory, more than the " &
                          //format_bytes(avail)//" available ("//source//"): reduce "//variable, error_code%value)
      end if
   end subroutine check_memory

   !> Upper estimate of the number of particles of a run: per sieve, the box volume times the
   !> fraction over the volume of the smallest particle passing it (volume_factor min_width**3).
   pure function particle_count_estimate(box, min_width, fraction) result(count)
      !> Box edges (mm).
      real(wp), intent(in) :: box(3)
      !> Per sieve: smallest width (mm).
      real(wp), intent(in) :: min_width(:)
      !> Per sieve: fraction of the box volume.
      real(wp), intent(in) :: fraction(:)
      real(wp) :: count
      integer :: s
      count = 0.0_wp
      do s = 1, min(size(min_width), size(fraction))
         if (min_width(s) > 0.0_wp) count = count + product(box) * max(0.0_wp, fraction(s)) &
                                             / (volume_factor * min_width(s)**3)
      end do
   end function particle_count_estimate

   !> Estimated memory (bytes) of a run of `particles` particles with `kinds` particle kinds and
   !> `nlayer` shell layers.
   pure function run_memory_estimate(particles, kinds, nlayer) result(bytes)
      !> Particle count (estimate).
      real(wp), intent(in) :: particles
      !> Number of particle kinds (shapes times sieves using them).
      real(wp), intent(in) :: kinds
      !> Shell layers.
      integer, intent(in) :: nlayer
      real(wp) :: bytes
      bytes = bytes_base + particles * (bytes_per_particle + 8.0_wp * nlayer) + kinds * bytes_per_kind &
              * (1 + nlayer)
   end function run_memory_estimate

   !> Memory (bytes) of `count` shapes of degree `nmax` (coefficients and bookkeeping).
   pure function shape_memory(count, nmax) result(bytes)
      !> Number of shapes.
      real(wp), intent(in) :: count
      !> Degree.
      integer, intent(in) :: nmax
      real(wp) :: bytes
      bytes = count * (256.0_wp + 48.0_wp * real(nmax + 1, wp)**2)
   end function shape_memory
end module anm_core_resources
