:- module(node_memory,
          [ node_rss/1,                 % -Bytes
            node_memory_note_idle/0,
            node_memory_baseline/1,     % -Bytes
            node_memory_check/2         % +Budget, -Verdict
          ]).
:- autoload(library(readutil), [read_line_to_string/2]).

/** <module> The process's resident memory against the agents' budget

agent_bounds.pl counts what agents hold as their modules plus their
stacks; memory that C code allocates outside both (atoms, GMP integers,
memory streams, findall bags, malloc'ed buffers) is not in that count.
This module reads what the process really holds, its resident set size
(RSS, /proc/self/statm), and says whether it is over

    baseline + agent_memory_budget

where the *baseline* is the RSS when a bounded call last started while no
other bounded call ran (the node with no guest code running: its own
code, connections, agents' modules at rest), and the budget is the
largest agent_memory_budget of the process's nodes that run calls. The
bounds monitor (agent_bounds.pl) asks at each tick; over the limit it
stops the running call that has used most CPU time (one per tick), and
reclaims (atom and clause garbage collection, trim_heap/0). Memory the
process cannot give back raises the next baseline: a bound on what
guests take at a time, not on what the node holds in all.

Reading /proc/self/statm takes about 10 us; where it does not exist (not
Linux) node_rss/1 fails and the check says `unknown`.
*/

:- dynamic baseline_/1, page_size_/1.

%!  node_rss(-Bytes) is semidet.
%
%   Resident set size of this process, from /proc/self/statm.

node_rss(Bytes) :-
    catch(setup_call_cleanup(open('/proc/self/statm', read, In),
                             read_line_to_string(In, Line),
                             close(In)),
          _, fail),
    string(Line),
    split_string(Line, " ", "", [_, RssS|_]),
    number_string(Pages, RssS),
    page_size(Page),
    Bytes is Pages * Page.

%   The page size: VmRSS of /proc/self/status (kB) over statm's pages,
%   rounded to a power of two; 4096 if that cannot be read.
page_size(Page) :-
    (   page_size_(Page)
    ->  true
    ;   (   measured_page_size(P0) -> Page = P0 ; Page = 4096 ),
        assertz(page_size_(Page))
    ).

measured_page_size(Page) :-
    catch(( read_file_to_lines('/proc/self/statm', [S|_]),
            split_string(S, " ", "", [_, RssS|_]),
            number_string(Pages, RssS),
            read_file_to_lines('/proc/self/status', Lines),
            member(L, Lines),
            split_string(L, ":", " \t", ["VmRSS", V]),
            split_string(V, " ", "", [KbS|_]),
            number_string(Kb, KbS)
          ), _, fail),
    Pages > 0,
    Ratio is Kb * 1024 / Pages,
    Page is 2 ** round(log(Ratio) / log(2)),
    Page >= 4096.

read_file_to_lines(File, Lines) :-
    setup_call_cleanup(open(File, read, In),
                       read_lines(In, Lines),
                       close(In)).

read_lines(In, Lines) :-
    read_line_to_string(In, L),
    (   L == end_of_file
    ->  Lines = []
    ;   Lines = [L|Rest],
        read_lines(In, Rest)
    ).

member(X, [X|_]).
member(X, [_|T]) :- member(X, T).

%!  node_memory_note_idle is det.
%
%   A bounded call starts while no other runs: the RSS now is the
%   baseline.

node_memory_note_idle :-
    (   node_rss(Rss)
    ->  retractall(baseline_(_)),
        assertz(baseline_(Rss))
    ;   true
    ).

%!  node_memory_baseline(-Bytes) is semidet.
%
%   The current baseline (see the module doc); fails before the first
%   bounded call.

node_memory_baseline(Bytes) :-
    baseline_(Bytes).

%!  node_memory_check(+Budget, -Verdict) is det.
%
%   Verdict is over(Rss, Limit) if the RSS is over baseline + Budget,
%   near(Rss, Limit) if over baseline + Budget/2, else ok(Rss, Limit),
%   or unknown (no RSS or no baseline yet).

node_memory_check(Budget, Verdict) :-
    must_be_bytes(Budget),
    (   baseline_(Base),
        node_rss(Rss)
    ->  Limit is Base + Budget,
        (   Rss > Limit
        ->  Verdict = over(Rss, Limit)
        ;   Rss > Base + Budget // 2
        ->  Verdict = near(Rss, Limit)
        ;   Verdict = ok(Rss, Limit)
        )
    ;   Verdict = unknown
    ).

must_be_bytes(B) :-
    (   integer(B), B >= 0
    ->  true
    ;   throw(error(type_error(nonneg, B), _))
    ).
